"""The calibration report (HTML with figures) for users who want to see what they can trust."""
