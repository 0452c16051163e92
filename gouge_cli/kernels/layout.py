"""Named indices of every array the kernels share with Python: the parameter vectors, the wall,
clock and counter records, the pair-list layout, the fluid grid's parameters, state and work rows,
the deposit's per-grain records, the observables, and the status codes the kernels return.

Every index has one name with one meaning: the DEM step's vectors (params ``N_PARAMS``, wall
``W_*``, clock ``C_*``, counters ``K_*``) and the fluid grid's (``P_*`` / ``N_FLUID_PARAMS``,
state ``S_*`` / ``N_FLUID_STATE``, work rows ``G_*`` / ``N_GRID_WORK``, corner rows ``CR_*``)
are distinct names. Shapes of the fluid arrays and the status codes: kernels.fluid_update.
"""

from collections import namedtuple

# ---- DEM step (kernels.step, kernels.coupled) --------------------------------------------------

# The arrays of a scene travel into the kernels as three records addressed by field name
# (namedtuples of arrays: numba compiles one specialisation per record type, and a field access
# is free). Field names are model.state.State's attribute names; adding a per-grain field means
# adding it here and allocating it in State (kernels.step.renumber re-orders the per-grain ones).
# per grain (N,): float64 except body (int8, FREE/BOTTOM/TOP), id (int64, original number);
# top: int64 (N_top,) current numbers of the top-wall grains
Grains = namedtuple("Grains", ("x", "z", "vx", "vz", "spin", "radius", "mass", "inv_mass", "inv_inertia", "body",
                               "force_x", "force_z", "torque", "top", "id"))
# the half neighbour list (kernels.neighbors) and its scratch: start (N + 1,) int64 row offsets,
# index int32 / shear float64 (capacity,) per pair slot, the list by second grain rev_start
# (N + 1,) int64 / rev_slot (capacity,) int32 (kernels.forces.reverse_list), x_build/z_build (N,)
# positions at the last build, new_* the rebuild's second buffers, layout int64 (N_LAYOUT,),
# cell_of/order (N,) and cell_count (2N + 64,) int64 (cell_of between rebuilds: the per-grain
# flags of the skin check; cell_count: scratch, also of kernels.coupled's solve-and-drift tasks)
Lists = namedtuple("Lists", ("start", "index", "shear", "rev_start", "rev_slot", "x_build", "z_build",
                             "new_start", "new_index", "new_shear", "layout", "cell_of", "order", "cell_count"))
# the force pass's per-pair data: results pair_fx, pair_fz (force on j), pair_ti, pair_tj (torques)
# float64 (capacity,) (the GPU engine's; the host's pass writes the sum_* tables); constants pair_const
# float64 (N_PAIR_CONST, capacity), rows PC_*, and pair_row int32 (capacity,), the first grain i of each
# slot; per-part chunk buffers pair_buf (parts, N_BUF, PAIR_BUF); the terms of the grains' sums, float64
# (2 capacity + 1,) each: sum_x, sum_z, sum_t at e = k the terms slot k adds to its second grain's sums
# (fx, fz, tj), at e = capacity + k those it adds to its first grain's (-fx, -fz, ti), at e = 2 capacity
# -0.0 (a term that adds nothing); sum_start (N + 1,) int64 and sum_end int32 (2 capacity + N + 2,):
# grain g's terms are e = sum_end[sum_start[g]:sum_start[g + 1]] in the order of its sums
# (kernels.forces.sum_list). pair_row, pair_const and the sum list are set with rev_start/rev_slot
# (layout[L_BUILT]).
Pairs = namedtuple("Pairs", ("pair_fx", "pair_fz", "pair_ti", "pair_tj", "pair_const", "pair_buf", "pair_row",
                             "sum_x", "sum_z", "sum_t", "sum_start", "sum_end"))

# params: float64 array
DT, WIDTH, SKIN, C_NORMAL, C_TANGENTIAL, DAMPING, FRICTION, SIGMA, SPRING, V_LOAD, \
    WALL_MASS, BG_DAMPING, DRIVE, THREADS, SORT_EVERY = range(15)
N_PARAMS = 15
# body codes (state.body)
FREE, BOTTOM, TOP = 0, 1, 2
# wall: float64 array, the top body
W_X, W_Z, W_VX, W_VZ, W_FX, W_FZ = range(6)
N_WALL = 6
# clock: float64 array (C_ANCHOR: spring stretch at the start of loading [d])
C_TIME, C_DRIVE_TIME, C_ANCHOR = range(3)
N_CLOCK = 3
# counters: int64 array
K_STEP, K_REBUILDS, K_PAIRS, K_NEED_REBUILD, K_NEEDED_CAPACITY, K_PHASE = range(6)
N_COUNTERS = 6
# counters[K_NEED_REBUILD]: 0, 1 (rebuild after the next drift) or MID_STEP (drifted, rebuild pending)
MID_STEP = 2
# phases (counters[K_PHASE])
COMPACTION, LOADING = 0, 1
# return codes of advance
OK, LIST_OVERFLOW, FLUID_FAILED = 0, 1, 2


# layout: int64 (N_LAYOUT,): layout[L_BUILT] is 1 while rev_start/rev_slot and the pair constants
# match the list and the masses, -1 once either changed (contact_forces then recomputes them,
# see model.state.State.list_changed); layout[L_SCRATCH:] the list build's
# per-block counters (kernels.neighbors.build_neighbors, 2 LIST_BLOCKS + 1)
LIST_BLOCKS = 16    # row blocks of a parallel list build
L_BUILT, L_SCRATCH = 0, 1
N_LAYOUT = L_SCRATCH + 2 * LIST_BLOCKS + 1
PARTS_PER_THREAD = 4    # parts of each force pass per thread, when threads > 1
# pair_buf: float64 (parts, N_BUF, PAIR_BUF), per-part chunk of the pair inputs gathered per step
B_DX, B_DZ, B_DVX, B_DVZ, B_WI, B_WJ = range(6)
N_BUF = 6
# pair_const rows: radii R_i, R_j [d], effective radius and reduced mass (kernels.contact.pair_constants)
PC_RI, PC_RJ, PC_REFF, PC_MEFF = range(4)
N_PAIR_CONST = 4
PAIR_BUF = 256

# ---- fluid grid (kernels.deposit, pressure, drag, fluid_update; model.fluid.FluidGrid) ----------
# fluid params: float64 (N_FLUID_PARAMS,); fluid state: float64 (N_FLUID_STATE,);
# work: float64 (N_GRID_WORK, nx, nz) scratch rows
P_KAPPA_C = 0        # Carman-Kozeny prefactor kappa_c [d^2]
P_BETA = 1           # fluid compressibility beta [1/E]
P_ETA = 2            # fluid viscosity eta [E t0]
P_SOLVER = 3         # SOLVER_IMPLICIT, SOLVER_EXPLICIT or SOLVER_AUTO
P_SAFETY = 4         # fraction of the FTCS bound per explicit sub-step [-]
P_TOL = 5            # CG relative residual tolerance [-]
P_MAX_ITER = 6       # CG iteration limit
P_PHI_MIN = 7        # porosity clamp, lower (0.05)
P_PHI_MAX = 8        # porosity clamp, upper (0.9)
P_MAX_SUBSTEPS = 9   # explicit sub-step limit per fluid update
P_FILTER_WIDTH = 10  # coarse-graining filter width w [d] (kernels.filter; 0: none)
N_FLUID_PARAMS = 11

SOLVER_IMPLICIT = 0
SOLVER_EXPLICIT = 1
SOLVER_AUTO = 2       # one explicit (Heun) step while dt_f <= AUTO_EXPLICIT x the FTCS bound, else implicit
AUTO_EXPLICIT = 0.25  # (dt_f lambda <= 0.5 for every mode: Heun's error <= 1/3 of backward Euler's)

S_Z_BOT = 0          # bottom plane at the last update [d]
S_Z_TOP = 1          # top plane at the last update [d]
S_ITERATIONS = 2     # CG iterations of the last update
S_RESIDUAL = 3       # final relative residual of the last CG solve
S_SUBSTEPS = 4       # explicit sub-steps of the last update
S_DT_MAX = 5         # explicit stability bound of the last update [t0]
S_UPDATES = 6        # number of fluid updates since fluid_init
S_EXPLICIT_UPDATES = 7   # of them, those an explicit scheme did (solver explicit: FTCS; auto: Heun)
S_F_BOT = 8          # fluid force on the bottom plane [E d] (kernels.fluid_update.plane_forces)
S_F_TOP = 9          # fluid force on the top plane [E d]; added to the top-wall grains' drag_z
N_FLUID_STATE = 10

G_TX = 0             # conductance of face (i+1/2, j)
G_TZ = 1             # conductance of face (i, j+1/2), j < nz-1
G_TB = 2             # conductance of the Dirichlet wall face of a boundary cell
G_CAPACITY = 3       # beta phi
G_DIAG = 4           # diagonal of C/dt + L
G_RHS = 5            # right-hand side; P* before the solve
G_R = 6              # CG residual; after the solve, rows G_R..G_P hold the drag's interleaved
                     # (q, r_x, r_z) triples (kernels.drag.interleave_triples)
G_Z = 7              # preconditioned residual
G_P = 8              # CG direction
G_Q = 9              # operator times direction; explicit scratch
G_CP = 10            # tridiagonal factor: modified upper coefficient, transposed (nz, nx)
G_DINV = 11          # tridiagonal factor: inverse pivot, transposed (nz, nx)
G_FQ = 12            # the consistent drag's fields (kernels.drag.drag_triples): q = P/s,
G_FX = 13            # r_x and r_z = (P/s^2) ds/dx, ds/dz, each filtered back by S^T
G_FZ = 14
G_SX = 15            # ds/dx consistent with the deposit
G_SZ = 16            # ds/dz consistent with the deposit
G_TZT = 17           # tz transposed (nz, nx), for the z-line solves (kernels.pressure)
G_LINE = 18          # the z-line solves' right-hand side and solution, transposed (nz, nx)
G_PREV = 19          # P^n at the start of an update; then the pressure extrapolated for the drag
G_TMP = 20           # the filter's scratch: rows G_TMP .. G_TMP + N_FILTER_SCRATCH - 1, one per field
N_FILTER_SCRATCH = 5     # (the deposit's five fields filtered at once: kernels.fluid_update.grid_stage)
N_GRID_WORK = G_TMP + N_FILTER_SCRATCH

# the deposit's inputs and outputs (kernels.deposit): the discs it reads, float64[>= n] each
# (x, z [d], vx, vz [v0], radius [d]); the wall planes now and their velocities over the fluid step
# (z_bot, z_top [d], w_bot, w_top [v0]); the five grid fields it writes, float64[nx, nz] each
# (s, ux, uz relative to the grid, grad_s_x, grad_s_z)
Discs = namedtuple("Discs", ("x", "z", "vx", "vz", "radius"))
Planes = namedtuple("Planes", ("z_bot", "z_top", "w_bot", "w_top"))
Deposited = namedtuple("Deposited", ("s", "ux", "uz", "grad_s_x", "grad_s_z"))

# the grid's arrays as kernels.coupled takes them, addressed by name (model.fluid.FluidGrid.record;
# shapes: kernels.fluid_update's module doc)
FluidArrays = namedtuple("FluidArrays", ("params", "state", "pressure", "s", "s_old", "ux", "uz", "permeability",
                                         "div_u", "work", "corners", "partial", "taps_x", "bands_z"))

STATUS_OK = 0
STATUS_SOLVER = 1
STATUS_NONFINITE = 2

DEPOSIT_GROUPS = 4     # grains deposit in this many fixed groups, summed in group order
# corners rows: a grain's cell (i0, j0) as c00 + CELL_CODE (below), the areas its four cells
# (i0, j0), (i1, j0), (i0, j0 + 1), (i1, j0 + 1) receive, and d fz / dz (see cell_weights); then
# the velocity it deposits, vx and vz - w(z). (i1, j0) is c00 + nz, less nx nz past the last column.
CR_CELL, CR_A00, CR_A10, CR_A01, CR_A11, CR_DFZ, CR_U, CR_W, CR_Z = range(9)   # CR_Z: (z - z_bot) / H
N_CORNERS = 9
# the cell row holds the float c00 + 2^52, exact, whose bits read as int64 are CELL_BITS + c00 (the
# float bits of 2^52 + v for integers 0 <= v < 2^52 are those of 2^52 plus v): vector loops write it,
# scalar loops read an integer without a float -> int conversion. A grain outside the layer has
# 2^52 - 1 there: negative either way (-1 as a float, -2 from the bits)
CELL_CODE = 2.0 ** 52
CELL_BITS = 0x4330000000000000
CELL_OUTSIDE = CELL_CODE - 1.0
# moments a grain adds to the record of its cell c00: its four shares a00, a10, a01, a11, the
# same times vx and times vz - w(z), and the z-slope terms (a00 + a01) dfz, (a10 + a11) dfz
M_S, M_U, M_W, M_G = 0, 4, 8, 12
M_FLAG = 15            # in the first record of a grid column: 1 if the group added to that column
M_H = 16               # the mirror shares of grad_z s (4): a W mu, mu = -+2/dz for a grain between a plane and
                       # the boundary cell centre (kernels.deposit: the mirror-extended deposit's gradient)
N_MOMENTS = 24         # (18 moments and the flag; padded so that a record is three cache lines)
N_SUMMED = 14

# ---- observables (kernels.measure) --------------------------------------------------------------
# observables: float64 (N_OBSERVABLES,), the vector measure.observe fills
KINETIC, COORDINATION, MAX_OVERLAP, POROSITY, THICKNESS, Z_BOTTOM, Z_TOP, BOTTOM_FX, BOTTOM_FZ, \
    NONFINITE, CONTACT_ENERGY, WORST_I, WORST_J = range(13)
N_OBSERVABLES = 13
