"""Estimators of cooperativeness: the paper's thresholded Kalman filter and better ones."""
