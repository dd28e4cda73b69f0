"""Synthetic rigs with known truth."""
