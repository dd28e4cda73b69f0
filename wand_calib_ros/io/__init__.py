"""File formats: rig description, observations CSV, result and camera_info YAML."""
