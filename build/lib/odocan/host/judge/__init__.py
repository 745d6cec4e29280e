"""The judge: float64 reference, pose pairing, analysis, live tracking, monitor model."""
