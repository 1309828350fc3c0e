"""Pose tracking (paper section 5, DigitEyes): IK on patch constraints, smoothing, covariances."""
