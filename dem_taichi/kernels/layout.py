"""Index constants of the small arrays passed to the kernels (plain Python, no Taichi).

``params`` (real): runtime physical/numerical parameters — changing them never recompiles; its
slots are generated from :data:`PARAMETER_SLOTS` (the engine's typed view of them:
:class:`dem_taichi.engine.parameters.EngineParameters`).
``cell`` (real): cell lengths, lengths at the last list build, time, list-displacement trackers.
``flags`` (int32): control and error flags set by kernels and read by the host.
``measures`` (real): sums accumulated by the measure kernel.
``fire`` (real): the FIRE minimiser's constants and running scalars (:mod:`.fire`).
Neighbour entries pack disc j with its periodic image (``IMAGE_*``, helpers for numpy code);
``pair_flags`` holds the ``PAIR_*`` bits of every list entry.
"""

# params ---------------------------------------------------------------------------------------
#: The slots of ``params``, in order: the one table of the runtime parameters. Each name is a
#: field of :class:`dem_taichi.engine.parameters.EngineParameters` (units and definitions there;
#: a test checks the two agree one to one); the ``P_*`` constants below are derived from it.
#: The order is the layout of states and checkpoints: new slots go at the end.
PARAMETER_SLOTS: tuple[str, ...] = (
    "time_step",
    "k_n",
    "gamma_n",
    "k_t",
    "gamma_t",
    "mu",
    "local_damping",
    "mass",
    "inertia",
    "diameter",
    "list_radius",
    "skin",
    "vdw_f_max",
    "vdw_k",
    "rate_x",
    "rate_y",
    "max_offset",
    "max_overlap",
    "reach",
    "cutoff",
    # bonded rods (docs/science/dem-model.md §1.7; unused by rigid rods)
    "spacing",
    "bond_k_n",
    "bond_k_t",
    "bond_k_b",
    "bond_gamma_n",
    "bond_gamma_t",
    "bond_gamma_b",
    "bond_breakage_force",
    # rolling resistance at inter-rod contacts (dem_taichi.physics.rolling; unused without it)
    "rolling_stiffness",
    "rolling_damping",
    "rolling_cap",
)


def parameter_slot(name):
    """The index of the runtime parameter ``name`` in ``params`` (a ``ValueError`` for a name
    not in :data:`PARAMETER_SLOTS`)."""
    return PARAMETER_SLOTS.index(name)


# the slots under the short names the kernels use (compile-time ints)
P_DT = parameter_slot("time_step")
P_KN = parameter_slot("k_n")
P_GN = parameter_slot("gamma_n")
P_KT = parameter_slot("k_t")
P_GT = parameter_slot("gamma_t")
P_MU = parameter_slot("mu")
P_ALPHA = parameter_slot("local_damping")
P_MASS = parameter_slot("mass")
P_INERTIA = parameter_slot("inertia")
P_DIAM = parameter_slot("diameter")
P_RLIST = parameter_slot("list_radius")
P_SKIN = parameter_slot("skin")
P_VDW_F = parameter_slot("vdw_f_max")
P_VDW_K = parameter_slot("vdw_k")
P_RATE_X = parameter_slot("rate_x")
P_RATE_Y = parameter_slot("rate_y")
P_MAX_OFFSET = parameter_slot("max_offset")
P_MAX_OVERLAP = parameter_slot("max_overlap")
P_REACH = parameter_slot("reach")
P_CUT = parameter_slot("cutoff")
P_SPACING = parameter_slot("spacing")
P_BOND_KN = parameter_slot("bond_k_n")
P_BOND_KT = parameter_slot("bond_k_t")
P_BOND_KB = parameter_slot("bond_k_b")
P_BOND_GN = parameter_slot("bond_gamma_n")
P_BOND_GT = parameter_slot("bond_gamma_t")
P_BOND_GB = parameter_slot("bond_gamma_b")
P_BOND_BREAK = parameter_slot("bond_breakage_force")
P_ROLL_K = parameter_slot("rolling_stiffness")
P_ROLL_G = parameter_slot("rolling_damping")
P_ROLL_CAP = parameter_slot("rolling_cap")
N_PARAMS = len(PARAMETER_SLOTS)

# cell -----------------------------------------------------------------------------------------
C_LX = 0
C_LY = 1
C_LBX = 2  # L_x at the last list build
C_LBY = 3
C_TIME = 4
C_VMAX = 5  # max disc speed bound during the last step
C_DISP = 6  # max disc displacement since the last list build
N_CELL = 8

# flags ----------------------------------------------------------------------------------------
F_STOP = 0  # a kernel asked the host to stop (overflow or blow-up)
F_OVERFLOW = 1  # the neighbour list capacity was too small
F_NEEDED = 2  # the largest neighbour count seen
F_OLD_SAVED = 3  # the previous list has been moved to the old buffers (rebuild pending)
F_FORCE_REBUILD = 4  # rebuild at the next step whatever the displacements
F_BLOWUP = 5  # 0 = fine, 1 = non-finite state, 2 = overlap beyond the bound
F_REBUILDS = 6  # number of list builds
F_STEPS = 7  # steps done in the current call
F_BLOWUP_INDEX = 8  # rod (code 1) or disc (code 2) that triggered the blow-up
# the parallel list build's decisions, shared by its loops and zero between launches
# (dem_taichi.kernels.parallel_lists)
F_BUILD_NOW = 9  # 1: the list is rebuilt in this step
F_BUILD_SAVE = 10  # 1: and the old list is moved to the old buffers first
F_BUILD_OVERFLOW = 11  # 1: a disc found more neighbours than the capacity
N_FLAGS = 12

BLOWUP_NONFINITE = 1
BLOWUP_OVERLAP = 2

# attraction partners ([long_range] attraction_pairs = "bonded_at_A") -------------------------
# row r of ``attraction_partners``: [n, partner rods 1..n, unused]; n = -1 until state A
# (every opposite-charge pair attracts), then the rods that rod r attracted at A
PARTNER_CAPACITY = 31  # partner rods per rod
PARTNER_COLUMNS = 1 + PARTNER_CAPACITY

# fire (the FIRE minimiser, dem_taichi.kernels.fire; set by the engine at each minimising call) --
FIRE_DT_MAX = 0  # Δt_max (absolute: factor × the scene's Δt)
FIRE_DT_MIN = 1  # Δt_min (absolute): Δt is not decreased below it
FIRE_N_DELAY = 2  # N_delay: steps with P > 0 before Δt grows; also FIRE 2.0's initial delay
FIRE_F_INC = 3  # Δt growth factor
FIRE_F_DEC = 4  # Δt decrease factor on P ≤ 0
FIRE_ALPHA_START = 5  # α after a reset
FIRE_F_ALPHA = 6  # α decay factor
FIRE_ALPHA = 7  # running α
FIRE_N_POS = 8  # running count of consecutive steps with P > 0
FIRE_N_NEG = 9  # running count of consecutive steps with P ≤ 0
FIRE_STEPS = 10  # steps of the minimisation so far (for the initial delay)
FIRE_RESETS = 11  # velocity resets (P ≤ 0) so far
FIRE_DT = 12  # running Δt of the minimisation (params[P_DT] holds it only while the kernel runs)
FIRE_DT0 = 13  # the scene's (runtime) Δt, put back into params[P_DT] at the end of every call
N_FIRE = 14

# measures -------------------------------------------------------------------------------------
M_SXX = 0  # Σ f_x b_x over inter-rod pairs and bonds (not yet divided by the area)
M_SXY = 1  # Σ f_x b_y
M_SYX = 2  # Σ f_y b_x
M_SYY = 3  # Σ f_y b_y
M_U_CONTACT = 4  # Σ ½ k_n δ² + ½ k_t ξ² (+ ½ κ_r ψ² with rolling resistance)
M_U_LONG = 5  # Σ long-range (and van der Waals) potential
M_CONTACTS = 6  # number of disc contacts (δ > 0)
M_LONG_PAIRS = 7  # number of disc pairs with a non-zero long-range or vdW force
M_SUM_PAIR_FORCE = 8  # Σ |F| over interacting pairs
M_KE_TRANS = 9  # Σ ½ M |v|² (full-step velocities)
M_KE_ROT = 10  # Σ ½ I ω²
M_SUM_ROD_FORCE = 11  # Σ_r |F_r|
M_SLIDING = 12  # number of contacts at the Coulomb cap
M_INTERACTING = 13  # number of interacting pairs (contact or non-zero long-range force)
M_U_BOND = 14  # Σ bond elastic energy (bonded rods)
M_BROKEN = 15  # number of broken bonds (bonded rods)
N_MEASURES = 16
# the mechanical coordination on the device (kernels.coordination), one pruning round
Z_REMOVED = 0  # rods removed as rattlers in the round
Z_ALIVE = 1  # rods left (with at least two contacts with other rods left)
Z_COUNTS = 2  # the sum of their contact counts (2 × the contacts between them)
N_COORDINATION = 3
#: rods, discs or bonds summed by one thread of kernels.measures.measure_sums_blocked
MEASURE_BLOCK = 64


def measure_block_rows(n_bodies: int, n_discs: int, bonded: bool) -> int:
    """Rows of the parallel measure's ``block_sums``: the body, disc and bond blocks."""
    bodies = -(-n_bodies // MEASURE_BLOCK)
    return bodies + -(-n_discs // MEASURE_BLOCK) + (bodies if bonded else 0)


# neighbour entries ----------------------------------------------------------------------------
# entry = j * IMAGE_CODES + code, code = (m_x + IMAGE_RANGE) * IMAGE_SIDE + (m_y + IMAGE_RANGE),
# with (m_x, m_y) the periodic image of disc j: r_ij = x_i − x_j − (m_x L_x, m_y L_y)
IMAGE_RANGE = 2  # image indices m in [−IMAGE_RANGE, IMAGE_RANGE]
IMAGE_SIDE = 2 * IMAGE_RANGE + 1  # 5
IMAGE_CODES = IMAGE_SIDE * IMAGE_SIDE  # 25


def image_code(m_x, m_y):
    """Code of the image (m_x, m_y) (ints or integer arrays)."""
    return (m_x + IMAGE_RANGE) * IMAGE_SIDE + (m_y + IMAGE_RANGE)


def image_of_code(code):
    """(m_x, m_y) of an image code (ints or integer arrays)."""
    return code // IMAGE_SIDE - IMAGE_RANGE, code % IMAGE_SIDE - IMAGE_RANGE


def mirrored_image_code(code):
    """Code of the opposite image (−m_x, −m_y): the entry of the pair seen from disc j."""
    m_x, m_y = image_of_code(code)
    return image_code(-m_x, -m_y)


# pair_flags bits (written by the measure kernel for every list entry) --------------------------
PAIR_CONTACT = 1  # the discs overlap (δ > 0)
PAIR_LONG_RANGE = 2  # a non-zero long-range or van der Waals force
PAIR_SLIDING = 4  # a contact at the Coulomb cap
PAIR_INTERACTING = 8  # any of the above
