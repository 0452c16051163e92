"""Post-processing of top-wall time series: slips, block-slider fits, friction, pair types.

Pure functions on numpy arrays (dimensionless units); no file I/O.
"""

from .blockslider import (
    BlockSliderFit,
    block_slider_duration,
    block_slider_peak_velocity,
    block_slider_prediction,
    block_slider_recurrence,
    block_slider_slip,
    fit_block_slider,
    simulate_block_slider,
)
from .friction import (
    dynamic_friction,
    effective_pressure,
    estimate_natural_frequency,
    mean_dynamic_friction,
    notch_filter,
    shear_resistance,
    spring_stress,
    wall_acceleration,
)
from .pairs import PairDefinition, PairResult, campaign_summary, classify_pair, complexity_criteria
from ..model.slip_rule import Slip, SlipDetector, SlipRule, SubEvent, WallSeries, detect_slips, recurrence_intervals

__all__ = [
    "BlockSliderFit",
    "PairDefinition",
    "PairResult",
    "Slip",
    "SlipDetector",
    "SlipRule",
    "SubEvent",
    "WallSeries",
    "block_slider_duration",
    "block_slider_peak_velocity",
    "block_slider_prediction",
    "block_slider_recurrence",
    "block_slider_slip",
    "campaign_summary",
    "classify_pair",
    "complexity_criteria",
    "detect_slips",
    "dynamic_friction",
    "effective_pressure",
    "estimate_natural_frequency",
    "fit_block_slider",
    "mean_dynamic_friction",
    "notch_filter",
    "recurrence_intervals",
    "shear_resistance",
    "simulate_block_slider",
    "spring_stress",
    "wall_acceleration",
]
