"""Scene-level reasoning: hypotheses, lifting of 2D detections to 3D, inference."""
