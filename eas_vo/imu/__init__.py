"""Every decision about the gyro, in one place: its readings' check before any work
(readings), the images' verdict after tracking (verdict), the axes and clock fit (fit), and the
policy the pipeline asks once (policy.assess)."""
