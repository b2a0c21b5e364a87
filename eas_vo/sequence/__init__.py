"""A recording as a whole: what it holds (info) and the recording written in the Event Camera
Dataset layout (convert).

Both read a dataset through the Dataset contract only (eas_vo.plugins), so they work for
every dataset plugin. Times are the dataset's own [s]: frames on the frames' clock, the IMU
on its own clock, ground truth on the ground truth's (before any run.*time_offset*).
"""
