"""The mathematics: mixtures, EM, model selection, registration, SE(3) and the odometry noise
model. Imports nothing of the other layers (see tests/test_layers.py)."""
