"""The calibration models: rigid body, linear, DNN, random forests, per-yaw residual forests, two-phase;
their input features and their model files (JSON, safetensors, skops; never a pickle)."""
