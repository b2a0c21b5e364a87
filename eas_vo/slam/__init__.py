"""Monocular ORB-SLAM3 in the loop (the paper's §4.3 and Table 2), through the optional
`slam` extra (pyorbslam3, GPL-3.0): vocabularies, the child process ORB-SLAM3 runs in, and the runs."""
