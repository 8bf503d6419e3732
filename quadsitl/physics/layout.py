"""Named slices of the state and parameter arrays: the only place their layout is written.

The state of N vehicles is one float64 array of shape (N, STATE_SIZE); a single vehicle
is a batch of one. Columns (world frame ENU, body frame FLU, quaternion (w, x, y, z)
rotating body into world):

==========  =======  ===========  ===============================
slice       columns  unit         meaning
==========  =======  ===========  ===============================
POS         0:3      m            position of the centre of mass, world ENU
VEL         3:6      m/s          velocity, world ENU
QUAT        6:10     –            attitude, body FLU -> world ENU
RATES       10:13    rad/s        body angular velocity, FLU
ROTORS      13:17    rad/s        rotor speeds Ω_1..Ω_4
==========  =======  ===========  ===============================

Parameters are one float64 array of shape (N, N_PARAMS), one row per vehicle, so that
every vehicle may carry its own airframe (domain randomisation). Rows are made by
:meth:`quadsitl.physics.airframe.Airframe.to_params`.
"""

from __future__ import annotations

N_ROTORS = 4

# --- state columns ---------------------------------------------------------------------
POS = slice(0, 3)
VEL = slice(3, 6)
QUAT = slice(6, 10)
RATES = slice(10, 13)
ROTORS = slice(13, 17)
STATE_SIZE = 17

# Scalar column indices for the compiled kernel (numba cannot index with slices cheaply).
I_PX, I_PY, I_PZ = 0, 1, 2
I_VX, I_VY, I_VZ = 3, 4, 5
I_QW, I_QX, I_QY, I_QZ = 6, 7, 8, 9
I_WX, I_WY, I_WZ = 10, 11, 12
I_ROTOR0 = 13

# --- parameter columns -----------------------------------------------------------------
P_MASS = 0  # kg
P_INERTIA = slice(1, 4)  # kg·m², diagonal (Jxx, Jyy, Jzz)
P_JXX, P_JYY, P_JZZ = 1, 2, 3
P_KT = 4  # N/(rad/s)²
P_KQ = 5  # N·m/(rad/s)²
P_KD = 6  # N/(m/s)²
P_KM = 7  # N·m/(rad/s)²
P_MOTOR_RATE = 8  # 1/s
P_OMEGA_MAX = 9  # rad/s
P_GRAVITY = 10  # m/s²
P_ROTOR_RADIUS = 11  # m
P_GEAR_HEIGHT = 12  # m
P_MAX_TOUCHDOWN_SPEED = 13  # m/s
P_COS_MAX_TILT = 14  # cos of the largest touchdown tilt
P_GROUND_Z = 15  # m, world height of the ground plane (−inf: no ground)
P_ROTOR_X = slice(16, 20)  # m, body x of each rotor hub
P_ROTOR_Y = slice(20, 24)  # m, body y of each rotor hub
P_ROTOR_YAW_SIGN = slice(24, 28)  # ±1, sign of each rotor's reaction torque about +z
P_ROTOR_X0, P_ROTOR_Y0, P_ROTOR_YAW_SIGN0 = 16, 20, 24
# The vehicle's world beyond the airframe, read only by the kernel's world build
# (quadsitl.physics.fleet.Fleet picks it once one of these is set; docs/physics.md):
P_GROUND_EFFECT = 28  # 1: Cheeseman–Bennett ground effect on every rotor, 0: none
P_ROTOR_EFFICIENCY = slice(29, 33)  # thrust and torque fraction per rotor: 1 healthy, 0 dead
P_ROTOR_EFFICIENCY0 = 29
N_PARAMS = 33

# --- ground contact state (one int8 per vehicle) ---------------------------------------
AIRBORNE = 0
ON_GROUND = 1  # resting on, or just touched down gently on, the ground
CRASHED = 2  # a rotor disc struck the ground, or touchdown too fast or too tilted
CONTACT_NAMES = {AIRBORNE: "airborne", ON_GROUND: "on_ground", CRASHED: "crashed"}

# --- wind parameters: one row per vehicle, shape (N, N_WIND_PARAMS) ----------------------
# Made by :meth:`quadsitl.physics.wind.Wind.to_params`; the model is in docs/physics.md.
W_MEAN_E, W_MEAN_N = 0, 1  # m/s, world ENU: mean wind (at 20 ft with the log profile)
W_LOG_PROFILE = 2  # 1: MIL-F-8785C logarithmic profile with height, 0: the same everywhere
W_TOWARD_E, W_TOWARD_N = 3, 4  # unit vector the mean wind blows toward: turbulence x axis
W_SIGMA_W = 5  # m/s, vertical turbulence intensity σ_w = 0.1·W20 (0: no turbulence)
W_SPAN = 6  # m, b of the angular-rate gust filters: the rotor-tip to rotor-tip span
W_GUST_E, W_GUST_N, W_GUST_U = 7, 8, 9  # m/s, 1-cosine gust amplitude, world ENU
W_GUST_LENGTH = 10  # m, d_m: distance over which the gust builds up (inf: no gust)
W_GUST_START = 11  # s after the vehicle's reset
W_GUST_HOLD = 12  # m, distance the gust holds its peak before it dies away the same way
W_ROLL_GAIN = 13  # m^(-1/6): σ_p = σ_w · W_ROLL_GAIN · L_w^(−1/3), from the span b
N_WIND_PARAMS = 14

# --- wind state: one row per vehicle, shape (N, N_WIND_STATE) -----------------------------
WS_TURBULENCE = slice(0, 8)  # Dryden shaping-filter states, dimensionless, in this order:
WS_U = 0  # longitudinal (first order)
WS_V1, WS_V2, WS_R = 1, 2, 3  # lateral pair and the yaw-rate gust filter
WS_W1, WS_W2, WS_Q = 4, 5, 6  # vertical pair and the pitch-rate gust filter
WS_P = 7  # roll-rate gust (first order)
WS_GUST_DISTANCE = 8  # m, distance flown through the air since the gust started
WS_TIME = 9  # s since the vehicle's reset
WS_AIR_VELOCITY = slice(10, 13)  # m/s, world ENU: the air's velocity at the vehicle
WS_AIR_RATES = slice(13, 16)  # rad/s, world ENU: the air's angular velocity (rate gusts)
WS_AIR_VE, WS_AIR_PE = 10, 13  # first columns of the two (for the compiled kernel)
N_WIND_STATE = 16
