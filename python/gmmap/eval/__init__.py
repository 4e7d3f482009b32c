"""Evaluation harnesses: the paper's experiments on real and simulated data."""
