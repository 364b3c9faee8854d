import json
import os
import tempfile
import unittest
from pathlib import Path

from lidar_har_train.outputs import OutputError, prepare_output, replaced_when_done, report_json, set_aside


class ReplacedWhenDone(unittest.TestCase):
    """export.py and pose_head.py write their model through `replaced_when_done`: a failed
    export must leave the model already at `--out` whole."""

    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.out = Path(self.dir.name) / "models" / "activity.onnx"

    def tearDown(self):
        self.dir.cleanup()

    def test_a_failed_block_leaves_the_file_and_no_temporary(self):
        self.out.parent.mkdir()
        self.out.write_bytes(b"the model trained yesterday")
        with self.assertRaises(RuntimeError):
            with replaced_when_done(self.out) as temp:
                temp.write_bytes(b"half an export")
                raise RuntimeError("parity")
        self.assertEqual(self.out.read_bytes(), b"the model trained yesterday")
        self.assertEqual(os.listdir(self.out.parent), ["activity.onnx"])

    def test_a_finished_block_replaces_the_file_in_a_new_folder(self):
        with replaced_when_done(self.out) as temp:
            self.assertFalse(self.out.exists())
            temp.write_bytes(b"new")
        self.assertEqual(self.out.read_bytes(), b"new")
        self.assertEqual(os.listdir(self.out.parent), ["activity.onnx"])

    def test_a_refused_file_is_set_aside_with_its_weights(self):
        self.out.parent.mkdir()
        self.out.write_bytes(b"old")
        with self.assertRaises(RuntimeError):
            with replaced_when_done(self.out) as temp:
                temp.write_bytes(b"refused")
                rejected = set_aside(temp, self.out)
                raise RuntimeError("parity")
        self.assertEqual(rejected, self.out.parent / "activity.rejected.onnx")
        self.assertEqual(rejected.read_bytes(), b"refused")
        self.assertEqual(self.out.read_bytes(), b"old")

    def test_a_folder_that_cannot_be_made_is_named_before_any_work(self):
        blocker = Path(self.dir.name) / "models"
        blocker.write_text("a file where the folder should be")
        with self.assertRaises(OutputError) as refused:
            prepare_output(self.out)
        self.assertIn(f"{self.out}: cannot make its folder {blocker}", str(refused.exception))


class ReportJson(unittest.TestCase):
    """train.py writes its report with `report_json`: `lidar-har evaluate` reads it (the
    train/test leak check) and refused the whole file over one bare NaN."""

    def test_non_finite_numbers_are_written_as_null(self):
        report = {"history": [{"epoch": 1, "loss": 0.5}, {"epoch": 2, "loss": float("nan")}],
                  "results": {"validation": {"accuracy_at_T": float("inf"), "recall_at_T": (None, -float("inf"))}},
                  "best_epoch": 1}
        text = report_json(report)
        self.assertEqual(json.loads(text, parse_constant=lambda name: self.fail(f"{name} in {text}")), {
            "history": [{"epoch": 1, "loss": 0.5}, {"epoch": 2, "loss": None}],
            "results": {"validation": {"accuracy_at_T": None, "recall_at_T": [None, None]}},
            "best_epoch": 1})
        self.assertTrue(text.endswith("}\n"))


if __name__ == "__main__":
    unittest.main()
