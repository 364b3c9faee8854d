"""The commands (train, pose_head) imported where PyTorch or ONNX Runtime is missing (.venv),
for what needs neither: their parsers, their metadata."""

import importlib
import importlib.util
import sys
import unittest
from unittest import mock


def import_command(test: unittest.TestCase, name: str):
    """`lidar_har_train.<name>`, with stand-ins for PyTorch and ONNX Runtime where they are
    missing. The stand-ins, and the modules imported with them, are dropped when `test` ends
    (from the package too): no other test meets them. Modules imported for real (onnx) stay:
    some cannot be imported twice."""
    package = importlib.import_module("lidar_har_train")
    known, modules = set(vars(package)), set(sys.modules)
    missing = [m for m in ("torch", "onnx", "onnxruntime")
               if m not in sys.modules and importlib.util.find_spec(m) is None]
    fakes = {m: mock.MagicMock() for m in missing}
    if "torch" in missing:
        fakes["torch.nn"] = fakes["torch"].nn
    sys.modules.update(fakes)

    def drop():
        for module in set(sys.modules) - modules:
            if module in fakes or module.startswith("lidar_har_train."):
                del sys.modules[module]
        for attribute in set(vars(package)) - known:
            delattr(package, attribute)

    test.addCleanup(drop)
    return importlib.import_module(f"lidar_har_train.{name}")
