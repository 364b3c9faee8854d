"""The training commands refuse option values that make no sense as the command line is read
(exit status 2, the option named), before any data is loaded. Runs without PyTorch too."""

import argparse
import io
import unittest
from contextlib import redirect_stderr
from unittest import mock

from lidar_har_train.arguments import at_least, number

from .stand_ins import import_command


class Types(unittest.TestCase):
    def test_at_least_names_the_bound_and_the_value(self):
        self.assertEqual(at_least(1)("3"), 3)
        self.assertEqual(at_least(0)("0"), 0)
        with self.assertRaisesRegex(argparse.ArgumentTypeError, r"^must be at least 1, got 0$"):
            at_least(1)("0")
        with self.assertRaises(ValueError):
            at_least(1)("2.5")

    def test_number_is_finite_and_within_its_bounds(self):
        fraction = number(above=0, below=1)
        self.assertEqual(fraction("0.15"), 0.15)
        for bad in ("0", "1", "1.5", "nan", "-inf"):
            with self.assertRaisesRegex(argparse.ArgumentTypeError,
                                        rf"^must be a finite number greater than 0 and below 1, got {bad}$"):
                fraction(bad)
        self.assertEqual(number(minimum=0)("0"), 0.0)
        with self.assertRaisesRegex(argparse.ArgumentTypeError, "at least 0, got -1e-9"):
            number(minimum=0)("-1e-9")
        with self.assertRaisesRegex(argparse.ArgumentTypeError, "got inf"):
            number(above=0)("inf")


class Commands(unittest.TestCase):
    def refused(self, name: str, work: str, argv: list[str]) -> str:
        """Runs `lidar_har_train.<name>.main(argv)`, whose `work` (what follows the parse)
        must not be reached; its stderr."""
        module = import_command(self, name)
        stderr = io.StringIO()
        with (mock.patch.object(module, work, side_effect=AssertionError(f"{argv} reached {work}")),
              redirect_stderr(stderr), self.assertRaises(SystemExit) as exit_):
            module.main(argv)
        self.assertEqual(exit_.exception.code, 2, stderr.getvalue())
        return stderr.getvalue()

    def test_train_refuses_nonsense_before_loading_data(self):
        for option, value, why in [
            ("--steps-per-epoch", "0", "must be at least 1, got 0"),
            ("--batch", "0", "must be at least 1, got 0"),
            ("--max-epochs", "0", "must be at least 1, got 0"),
            ("--patience", "0", "must be at least 1, got 0"),
            ("--hidden", "0", "must be at least 1, got 0"),
            ("--encoder-channels", "0", "must be at least 1, got 0"),
            ("--threads", "0", "must be at least 1, got 0"),
            ("--shift-px", "-1", "must be at least 0, got -1"),
            ("--seed", "-1", "must be at least 0, got -1"),
            ("--val-fraction", "1.5", "must be a finite number greater than 0 and below 1, got 1.5"),
            ("--val-fraction", "0", "must be a finite number greater than 0 and below 1, got 0"),
            ("--lr", "-1", "must be a finite number greater than 0, got -1"),
            ("--lr", "nan", "must be a finite number greater than 0, got nan"),
            ("--lr-final", "-1e-4", "must be a finite number at least 0, got -1e-4"),
            ("--time-budget-min", "0", "must be a finite number greater than 0, got 0"),
        ]:
            with self.subTest(option=option, value=value):
                stderr = self.refused("train", "train", ["--data", "nowhere", "--out", "m.onnx", f"{option}={value}"])
                self.assertIn(f"error: argument {option}: {why}", stderr)

    def test_pose_head_refuses_nonsense_before_loading_data(self):
        for option, value, why in [
            ("--minutes", "0", "must be a finite number greater than 0, got 0"),
            ("--batch", "0", "must be at least 1, got 0"),
            ("--lr", "0", "must be a finite number greater than 0, got 0"),
            ("--beta", "-0.1", "must be a finite number at least 0, got -0.1"),
            ("--validation-fraction", "1", "must be a finite number at least 0 and below 1, got 1"),
            ("--validation-fraction", "-0.1", "must be a finite number at least 0 and below 1, got -0.1"),
            ("--channels", "0", "must be at least 1, got 0"),
            ("--units", "0", "must be at least 1, got 0"),
            ("--threads", "0", "must be at least 1, got 0"),
            ("--train-windows", "-1", "must be at least 0, got -1"),
            ("--test-windows", "-1", "must be at least 0, got -1"),
            ("--first-step", "-1", "must be at least 0, got -1"),
            ("--seed", "-1", "must be at least 0, got -1"),
        ]:
            with self.subTest(option=option, value=value):
                stderr = self.refused("pose_head", "run", ["m.onnx", "nowhere", f"{option}={value}"])
                self.assertIn(f"error: argument {option}: {why}", stderr)

    def test_the_documented_zeros_are_taken(self):
        module = import_command(self, "pose_head")
        with mock.patch.object(module, "run", return_value=0) as run:
            self.assertEqual(module.main(["m.onnx", "d", "--train-windows", "0", "--test-windows", "0",
                                          "--validation-fraction", "0", "--beta", "0", "--first-step", "0"]), 0)
        args = run.call_args.args[0]
        self.assertEqual((args.train_windows, args.validation_fraction, args.first_step), (0, 0.0, 0))
        train = import_command(self, "train")
        args = train.parse_args(["--data", "d", "--out", "m.onnx", "--shift-px", "0", "--lr-final", "0"])
        self.assertEqual((args.shift_px, args.lr_final), (0, 0.0))


if __name__ == "__main__":
    unittest.main()
