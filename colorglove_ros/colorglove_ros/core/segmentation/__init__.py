"""Glove segmentation (paper section 3): colour model and calibration, clean-up, crop, blobs."""
