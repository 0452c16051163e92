"""The slip rule (gouge_cli.model.slip_rule): built once from a config, the same rule in every user, and
a detector state saved before the records were typed (one- and two-letter keys) still resumes."""

from __future__ import annotations

import json
import math

import numpy as np

from gouge_cli.config import SlipsConfig, build_config
from gouge_cli.model.slip_events import OpenEvent, SubTracker
from gouge_cli.model.slip_rule import SlipDetector, SlipRule


def _series(n=6000, seed=3):
    rng = np.random.default_rng(seed)
    t = np.arange(n) * 0.01
    V_s = 1e-3
    v = 0.3 * V_s * rng.standard_normal(n)
    for t0 in np.arange(3.0, t[-1] - 3.0, 7.0):
        v += 0.05 * np.exp(-0.5 * ((t - t0) / 0.4) ** 2) + 0.02 * np.exp(-0.5 * ((t - t0 - 1.2) / 0.3) ** 2)
    x = np.concatenate(([0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.01)))
    tau = 0.2 + 0.01 * (V_s * t - x)
    return t, x, v, tau, V_s


def _old_keys(state: dict) -> dict:
    """A detector state as checkpoints written before the typed records held it."""
    ev = {v: k for k, v in OpenEvent.OLD_KEYS.items()}
    sub = {v: k for k, v in SubTracker.OLD_KEYS.items()}
    out = json.loads(json.dumps(state))
    for key in ("raw", "pending"):
        if out[key] is not None:
            rec = {ev.get(k, k): v for k, v in out[key].items()}
            if rec.get("sub") is not None:
                rec["sub"] = {sub.get(k, k): v for k, v in rec["sub"].items()}
            out[key] = rec
    return out


def test_rule_from_config_has_the_config_defaults():
    cfg = build_config({})
    rule = SlipRule.from_config(cfg)
    defaults = SlipsConfig()
    assert rule.V_s == cfg.loading.velocity
    assert rule.config_values() == {k: float(getattr(defaults, k)) for k in SlipRule.CONFIG_KEYS}
    assert SlipRule.from_stored({}, rule.V_s) == rule
    assert math.isclose(rule.hi, defaults.start_factor * rule.V_s) and rule.lo < rule.hi


def test_old_detector_state_resumes_the_same():
    t, x, v, tau, V_s = _series()
    rule = SlipRule(V_s, merge_gap=0.5)
    whole = SlipDetector(rule)
    out_whole = [s for i in range(t.size) if (s := whole.update(t[i], x[i], v[i], tau[i])) is not None]
    saved_mid_event = 0
    det, out = SlipDetector(rule), []
    for i in range(t.size):
        if i % 997 == 0 and i:
            if det.raw is not None or det.pending is not None:
                saved_mid_event += 1
            det = SlipDetector.from_state_dict(_old_keys(det.state_dict()))
        if (s := det.update(t[i], x[i], v[i], tau[i])) is not None:
            out.append(s)
    assert len(out_whole) >= 3 and saved_mid_event >= 1
    np.testing.assert_equal([s.to_dict() for s in out], [s.to_dict() for s in out_whole])
