"""Collecting wand observations live: time sync across cameras, a persisted buffer, coverage (no ROS)."""
