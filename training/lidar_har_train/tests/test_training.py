"""Training, export and the pose head: need PyTorch and ONNX Runtime (training/.venv); skipped
without them (.venv, where tests/tests/training_python.rs runs the rest)."""

import gc
import importlib.util
import io
import json
import tempfile
import unittest
import weakref
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from types import SimpleNamespace
from unittest import mock

if not all(importlib.util.find_spec(m) for m in ("torch", "onnx", "onnxruntime")):
    raise unittest.SkipTest("needs PyTorch, onnx and ONNX Runtime (training/requirements.txt)")

from lidar_har_train import export, pose_head, train  # noqa: E402

from .synthetic import WINDOW, write_dataset  # noqa: E402

TINY = ["--hidden", "4", "--encoder-channels", "2", "--batch", "4", "--max-epochs", "2", "--steps-per-epoch", "3",
        "--threads", "1", "--seed", "3", "--skip-test-eval"]


def quietly(main, argv) -> tuple[int, str, str]:
    """`main(argv)`'s exit code, stdout and stderr."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with redirect_stdout(stdout), redirect_stderr(stderr):
        code = main(argv)
    return code, stdout.getvalue(), stderr.getvalue()


class Training(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.root = Path(self.dir.name)
        self.data = write_dataset(self.root / "data")

    def tearDown(self):
        self.dir.cleanup()

    def test_a_failed_export_leaves_the_model_at_out_whole(self):
        out = self.root / "models" / "activity.onnx"
        out.parent.mkdir()
        out.write_bytes(b"the model trained yesterday")
        with mock.patch.object(export, "PARITY_TOLERANCE", 0.0):
            code, _, stderr = quietly(train.main, ["--data", str(self.data), "--out", str(out), *TINY])
        self.assertEqual(code, 1, stderr)
        self.assertEqual(out.read_bytes(), b"the model trained yesterday")
        self.assertIn("train: error: parity check failed", stderr)
        self.assertIn(f"{out} is not written, the refused export is {out.parent / 'activity.rejected.onnx'}", stderr)
        # The refused export keeps the run's weights: the model can be rebuilt from it.
        export.model_from_onnx(out.parent / "activity.rejected.onnx")
        self.assertEqual(sorted(p.name for p in out.parent.iterdir()), ["activity.onnx", "activity.rejected.onnx"])

    def test_a_model_whose_outputs_are_nan_fails_the_parity_check(self):
        # Python's max(0.0, nan) is 0.0: a NaN difference used to vanish and the check pass.
        out = self.root / "models" / "activity.onnx"
        out.parent.mkdir()
        step = train.ActivityConvLSTM.step

        def poisoned(model, x, h, c):
            logits, h, c = step(model, x, h, c)
            return logits * float("nan"), h, c

        with mock.patch.object(train.ActivityConvLSTM, "step", poisoned):
            code, _, stderr = quietly(train.main, ["--data", str(self.data), "--out", str(out), *TINY])
        self.assertEqual(code, 1, stderr)
        self.assertIn("train: error: parity check failed", stderr)
        self.assertFalse(out.exists())

    def test_the_first_steps_rate_does_not_depend_on_the_wall_time(self):
        args = train.parse_args(["--data", "d", "--out", "o.onnx"])
        budget_s = 60 * args.time_budget_min
        self.assertEqual(train.learning_rate(args, 0, 0, 0.3), args.lr)
        # A slow first step (a GPU's warm-up) does not move the rate off the steps' schedule.
        self.assertEqual(train.learning_rate(args, 0, 1, 0.01 * budget_s), train.learning_rate(args, 0, 1, 0.0))
        # A budget that binds still takes the rate to --lr-final when it runs out.
        self.assertAlmostEqual(train.learning_rate(args, 0, 5, budget_s), args.lr_final, places=12)
        self.assertLess(train.learning_rate(args, 0, 5, 0.5 * budget_s), train.learning_rate(args, 0, 5, 0.0))

    def test_a_fixed_seed_repeats_a_run_whose_epochs_bind(self):
        models = []
        for seconds_per_call in (0.2, 0.5):
            # The two runs' wall clocks differ; the 10-minute budget binds in neither.
            clock = iter(range(1000))
            fake_time = SimpleNamespace(monotonic=lambda: seconds_per_call * next(clock))
            out = self.root / str(seconds_per_call) / "model.onnx"
            with mock.patch.object(train, "time", fake_time):
                code, _, stderr = quietly(train.main, ["--data", str(self.data), "--out", str(out), *TINY,
                                                       "--time-budget-min", "10"])
            self.assertEqual(code, 0, stderr)
            models.append(out.read_bytes())
        self.assertEqual(models[0], models[1])

    def test_the_whole_train_split_is_not_kept_beside_its_two_parts(self):
        load_split, alive = train.load_split, []

        def loading(data, index, name, mapped=False):
            split = load_split(data, index, name, mapped)
            if name == "train":
                alive.append(weakref.ref(split.images))
            return split

        def after_the_split(labels):
            gc.collect()
            raise RuntimeError(f"whole split held: {alive[0]() is not None}")

        with mock.patch.object(train, "load_split", loading), \
                mock.patch.object(train, "class_weights_for_sampling", after_the_split), \
                self.assertRaises(RuntimeError) as stopped, redirect_stdout(io.StringIO()):
            train.train(train.parse_args(["--data", str(self.data), "--out", str(self.root / "m.onnx"), *TINY]))
        self.assertEqual(str(stopped.exception), "whole split held: False")

    def test_a_missing_array_is_an_error_not_a_traceback(self):
        (self.data / "train_labels.npy").unlink()
        code, _, stderr = quietly(train.main, ["--data", str(self.data), "--out", str(self.root / "m.onnx"), *TINY])
        self.assertEqual(code, 1)
        self.assertIn(f"train: error: {self.data / 'train_labels.npy'}: cannot read the array", stderr)


class PoseHead(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.dir = tempfile.TemporaryDirectory()
        cls.root = Path(cls.dir.name)
        cls.data = write_dataset(cls.root / "data")
        cls.model = cls.root / "activity.onnx"
        code, _, stderr = quietly(train.main, ["--data", str(cls.data), "--out", str(cls.model), *TINY])
        assert code == 0, stderr

    @classmethod
    def tearDownClass(cls):
        cls.dir.cleanup()

    def pose_head(self, *options, data=None):
        return quietly(pose_head.main, [str(self.model), str(data or self.data), "--minutes", "0.002",
                                        "--first-step", "3", "--threads", "1", *options])

    def test_out_in_a_new_folder_and_the_scores_before_the_export(self):
        out, scores = self.root / "new" / "heads" / "pose.onnx", self.root / "other" / "scores.json"
        with mock.patch.object(pose_head, "PARITY_TOLERANCE", 0.0):
            code, _, stderr = self.pose_head("--out", str(out), "--json", str(scores))
        self.assertEqual(code, 1, stderr)
        self.assertIn("pose_head: error: pose head parity check failed", stderr)
        self.assertFalse(out.exists())
        self.assertTrue((out.parent / "pose.rejected.onnx").exists())
        self.assertIn("activities", json.loads(scores.read_text()))

        code, stdout, stderr = self.pose_head("--out", str(out), "--json", str(scores))
        self.assertEqual(code, 0, stderr)
        self.assertIn(f"wrote {out}", stdout)
        self.assertIn("parity_max_abs_diff", json.loads(scores.read_text()))

    def test_an_out_that_cannot_be_written_fails_before_any_split_is_read(self):
        blocker = self.root / "blocker"
        blocker.write_text("a file where the folder should be")
        for option in ("--out", "--json"):
            code, stdout, stderr = self.pose_head(option, str(blocker / "pose.onnx"))
            self.assertEqual(code, 1, stderr)
            self.assertIn(f"pose_head: error: {blocker / 'pose.onnx'}: cannot make its folder", stderr)
            self.assertNotIn("seen scans", stdout)

    def test_a_first_step_past_the_window_is_named_before_any_split_is_read(self):
        code, stdout, stderr = self.pose_head("--first-step", str(WINDOW))
        self.assertEqual(code, 1, stderr)
        self.assertIn(f"pose_head: error: --first-step {WINDOW}: the windows of {self.data} have {WINDOW} scans",
                      stderr)
        self.assertNotIn("seen scans", stdout)

    def test_dataset_errors_are_named_not_tracebacks(self):
        code, _, stderr = self.pose_head(data=self.root / "nowhere")
        self.assertEqual(code, 1)
        self.assertIn(f"pose_head: error: {self.root / 'nowhere' / 'index.json'}: no index.json", stderr)

        cut = write_dataset(self.root / "cut")
        positions = cut / "test_positions.npy"
        positions.write_bytes(positions.read_bytes()[:200])
        code, _, stderr = self.pose_head(data=cut)
        self.assertEqual(code, 1)
        self.assertIn(f"pose_head: error: {positions}: not a whole .npy array", stderr)


if __name__ == "__main__":
    unittest.main()
