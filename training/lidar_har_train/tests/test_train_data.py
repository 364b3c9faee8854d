"""What the training and export commands do with the dataset before any PyTorch work: runs
without PyTorch too (stand-ins)."""

import io
import tempfile
import tracemalloc
import unittest
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from unittest import mock

import numpy as np

from .stand_ins import import_command
from . import synthetic
from .synthetic import SIZE, write_dataset


class BeforeTraining(unittest.TestCase):
    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.addCleanup(self.dir.cleanup)
        self.root = Path(self.dir.name)
        self.train = import_command(self, "train")

    def main(self, data: Path, *options: str) -> tuple[int, str]:
        """`train.main`'s exit code and stderr."""
        stderr = io.StringIO()
        with redirect_stderr(stderr), redirect_stdout(io.StringIO()):
            code = self.train.main(["--data", str(data), "--out", str(self.root / "m.onnx"), "--device", "cpu",
                                    *options])
        return code, stderr.getvalue()

    def test_a_shift_of_half_the_image_or_more_is_refused_before_the_data_is_read(self):
        # A shift past the image's side crashed the first batch with numpy's ValueError;
        # one of half the image moved the person out of it.
        data = write_dataset(self.root / "data")
        read = self.train.DatasetError("the train split was read")
        with mock.patch.object(self.train, "load_split", side_effect=read):
            for shift in (SIZE // 2, SIZE, 40):
                with self.subTest(shift=shift):
                    code, stderr = self.main(data, "--shift-px", str(shift))
                    self.assertEqual(code, 1, stderr)
                    self.assertEqual(stderr, f"train: error: --shift-px {shift}: the dataset's images are {SIZE} "
                                             f"pixels wide, and a shift of half that or more moves the person out "
                                             f"of the image (at most {SIZE // 2 - 1})\n")
            code, stderr = self.main(data, "--shift-px", str(SIZE // 2 - 1))
            self.assertEqual((code, stderr), (1, "train: error: the train split was read\n"))
        window = np.full((2, SIZE, SIZE), 255, np.uint8)
        shifted = self.train.augment(window[None], np.random.default_rng(1), SIZE // 2 - 1)
        self.assertEqual(shifted.shape, (1, 2, SIZE, SIZE))

    def test_the_train_split_is_in_memory_once_while_validation_is_split_off(self):
        # Loaded whole, the split's images were in memory beside the two parts copied from it:
        # twice the images at the peak.
        # Large images, few windows: the heap's other contents (the index) stay small beside them.
        with mock.patch.object(synthetic, "SIZE", 64):
            data = synthetic.write_dataset(self.root / "data", {"train": 6}, windows_per_episode=50)
        images = np.load(data / "train_images.npy", mmap_mode="r").nbytes
        split_validation = self.train.split_validation
        parts = []

        def split_then_stop(split, *args):
            parts.extend(split_validation(split, *args))
            raise self.train.DatasetError("validation split off")

        with mock.patch.object(self.train, "split_validation", split_then_stop):
            tracemalloc.start()
            try:
                code, stderr = self.main(data)
                _, peak = tracemalloc.get_traced_memory()
            finally:
                tracemalloc.stop()
        self.assertEqual((code, stderr), (1, "train: error: validation split off\n"))
        self.assertEqual(sum(part.images.nbytes for part in parts), images)
        self.assertFalse(any(isinstance(part.images, np.memmap) for part in parts))
        self.assertLess(peak, 1.3 * images, f"heap peak {peak} bytes for {images} bytes of images")


class ExportRecheck(unittest.TestCase):
    def test_the_recheck_reads_only_the_windows_it_steps(self):
        export = import_command(self, "export")
        with tempfile.TemporaryDirectory() as root:
            data = write_dataset(Path(root) / "data")
            figures = {name: {"max_abs_diff": 0.0, "max_abs_value": 1.0} for name in ("logits", "h_next", "c_next")}
            with (mock.patch.object(export, "model_from_onnx"),
                  mock.patch.object(export, "parity", return_value={"step": figures, "window": figures}) as parity,
                  redirect_stdout(io.StringIO())):
                self.assertEqual(export.main(["--model", "m.onnx", "--data", str(data)]), 0)
        windows = parity.call_args.args[2]
        self.assertIsInstance(windows, np.memmap)
        self.assertEqual(len(windows), 8)


if __name__ == "__main__":
    unittest.main()
