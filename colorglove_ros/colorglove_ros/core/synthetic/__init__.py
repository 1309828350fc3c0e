"""Synthetic data with ground truth: renderer, imaging conditions, frames, sequences."""
