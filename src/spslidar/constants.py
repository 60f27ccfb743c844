"""Physical constants."""

SPEED_OF_LIGHT = 299_792_458.0  # m/s
#: the farthest depth a scene, a depth window or a range gate may hold, in metres
#: (single-photon lidar has ranged ~200 km; a larger value is a unit mistake, and would
#: overflow the range gate's arithmetic)
MAX_DEPTH_M = 1e6
#: the most delay bins a range gate may span (16.8 M: 134 MB of lags, and range slices of
#: at least 1 GB even at 4x4 pixels; beyond it the arrays would not exist before the memory
#: check could refuse the run)
MAX_GATE_BINS = 2 ** 24
#: largest mean counts per TDC bin: counts are float32, exact integers up to 2^24
MAX_COUNT_MEAN = 2 ** 24 * 0.9
