"""The export's parity limit (docs/training.md, "Export"): 1e-5 absolute on every output.
Runs without PyTorch too (stand-ins)."""

import json
import unittest
from pathlib import Path

from .stand_ins import import_command

COMMITTED_REPORT = Path(__file__).resolve().parents[3] / "models" / "activity.training.json"


class ParityLimit(unittest.TestCase):
    def setUp(self):
        self.export = import_command(self, "export")

    def test_each_output_is_held_to_1e5_absolute_whatever_its_magnitude(self):
        # Scaled by the largest magnitude (logits up to 10, c up to 17), 1.6e-4 used to pass.
        figures = {
            "logits": {"max_abs_diff": 1.0e-4, "max_abs_value": 10.2},
            "h_next": {"max_abs_diff": 9.9e-6, "max_abs_value": 1.0},
            "c_next": {"max_abs_diff": 1.1e-5, "max_abs_value": 16.8},
        }
        self.assertEqual(sorted(self.export.outside_tolerance(figures)), ["c_next", "logits"])
        nan = {"logits": {"max_abs_diff": float("nan"), "max_abs_value": float("nan")}}
        self.assertEqual(list(self.export.outside_tolerance(nan)), ["logits"])

    def test_the_committed_models_export_is_within_the_limit(self):
        parity = json.loads(COMMITTED_REPORT.read_text())["parity"]
        self.assertEqual(self.export.outside_tolerance(parity["step"]), {})


if __name__ == "__main__":
    unittest.main()
