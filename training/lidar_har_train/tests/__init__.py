"""Tests of lidar_har_train: `python -m unittest discover -s training/lidar_har_train/tests -t training`
(run by tests/tests/training_python.rs with .venv, which has no PyTorch: the tests that train
or export skip there, and run in training/.venv)."""
