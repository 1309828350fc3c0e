"""Evaluation against ground truth: metrics, per-frame evaluation sequences, lookup diagnosis."""
