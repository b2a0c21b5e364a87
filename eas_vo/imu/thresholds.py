"""The thresholds more than one of the gyro's checks reads, defined once."""

import numpy as np

#: Pairs over which neither the gyro nor the images turned this much [rad] (0.5 deg) carry no
#: direction or size to compare.
MIN_TURN_RAD = float(np.radians(0.5))
#: The fewest frame pairs the axes and clock fit (fit.imu_agreement) compares, and the fewest
#: agreeing ones it takes to say anything about the gyro's axes or clock (policy).
MIN_AGREEMENT_PAIRS = 20
