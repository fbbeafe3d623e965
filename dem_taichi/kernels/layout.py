"""Index constants of the small arrays passed to the kernels (plain Python, no Taichi).

``params`` (real): runtime physical/numerical parameters — changing them never recompiles.
``cell`` (real): cell lengths, lengths at the last list build, time, list-displacement trackers.
``flags`` (int32): control and error flags set by kernels and read by the host.
``measures`` (real): sums accumulated by the measure kernel.
``fire`` (real): the FIRE minimiser's constants and running scalars (:mod:`.fire`).
Neighbour entries pack disc j with its periodic image (``IMAGE_*``, helpers for numpy code);
``pair_flags`` holds the ``PAIR_*`` bits of every list entry.
"""

# params ---------------------------------------------------------------------------------------
P_DT = 0  # time step Δt
P_KN = 1  # normal stiffness k_n
P_GN = 2  # normal damping γ_n
P_KT = 3  # tangential stiffness k_t
P_GT = 4  # tangential damping γ_t
P_MU = 5  # Coulomb friction μ
P_ALPHA = 6  # local non-viscous damping α
P_MASS = 7  # rod mass M
P_INERTIA = 8  # rod moment of inertia I
P_DIAM = 9  # disc diameter d
P_RLIST = 10  # list radius: interaction cut-off + skin (centre distance)
P_SKIN = 11  # Verlet skin
P_VDW_F = 12  # van der Waals F_w
P_VDW_K = 13  # van der Waals k_w
P_RATE_X = 14  # cell strain rate along x, compression positive (ε̇_xx = −L̇_x/L_x)
P_RATE_Y = 15  # same along y
P_MAX_OFFSET = 16  # max |o_s| of a disc from its rod centroid
P_MAX_OVERLAP = 17  # blow-up bound on δ (absolute)
P_REACH = 18  # bound on the centroid branch vector of a listed pair (rod length + list radius)
P_CUT = 19  # interaction cut-off (centre distance): d, or d + max range of the long-range laws
# bonded rods (docs/science/dem-model.md §1.7; unused by rigid rods)
P_SPACING = 20  # bond rest length s_0 (the rods' centre spacing)
P_BOND_KN = 21  # bond stretch stiffness k_bn
P_BOND_KT = 22  # bond shear stiffness k_bt
P_BOND_KB = 23  # bond bending stiffness κ_b
P_BOND_GN = 24  # bond stretch damping γ_bn
P_BOND_GT = 25  # bond shear damping γ_bt
P_BOND_GB = 26  # bond bending damping γ_bb
P_BOND_BREAK = 27  # breakage tension F_b (≤ 0: unbreakable)
# rolling resistance at inter-rod contacts (dem_taichi.physics.rolling; unused without it)
P_ROLL_K = 28  # κ_r = k_r d_eff², moment per radian of the rolling spring ψ
P_ROLL_G = 29  # η_r = γ_r d_eff², moment damping per unit relative rotation rate
P_ROLL_CAP = 30  # μ_r d_eff: the rolling moment cap per unit contact force
N_PARAMS = 31

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
N_FLAGS = 12

BLOWUP_NONFINITE = 1
BLOWUP_OVERLAP = 2

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
