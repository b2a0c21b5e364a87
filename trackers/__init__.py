"""Tracker plugins; installed as `eas_vo.trackers`."""
