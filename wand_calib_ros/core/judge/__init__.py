"""Judgements on data and results: data that cannot determine a calibration, results that cannot be
physically right, a calibration's quality in plain words, diagnostics, and accuracy against a truth."""
