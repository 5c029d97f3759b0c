"""Training data: datasets and their windows, input curves, the embedded synthetic dataset, exports."""
