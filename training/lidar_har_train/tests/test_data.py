import tempfile
import unittest
from pathlib import Path

from lidar_har_train.data import DatasetError, load_index, load_split

from .synthetic import write_dataset


class ReadingArrays(unittest.TestCase):
    """A missing or cut-short `.npy` is a DatasetError naming the file (train, pose_head,
    export and the sweep report those as `...: error: ...`), not a traceback."""

    def setUp(self):
        self.dir = tempfile.TemporaryDirectory()
        self.data = write_dataset(Path(self.dir.name))
        self.index = load_index(self.data)

    def tearDown(self):
        self.dir.cleanup()

    def assert_refused(self, name: str, mapped: bool, needle: str):
        with self.assertRaises(DatasetError) as refused:
            load_split(self.data, self.index, "train", mapped=mapped)
        self.assertIn(str(self.data / name), str(refused.exception))
        self.assertIn(needle, str(refused.exception))

    def test_a_missing_array_is_named(self):
        (self.data / "train_labels.npy").unlink()
        self.assert_refused("train_labels.npy", False, "cannot read the array: No such file or directory")

    def test_a_cut_short_array_is_named(self):
        path = self.data / "train_images.npy"
        path.write_bytes(path.read_bytes()[:1000])
        for mapped in (False, True):
            self.assert_refused("train_images.npy", mapped, "not a whole .npy array")

    def test_an_empty_or_headless_array_is_named(self):
        path = self.data / "train_positions.npy"
        for cut in (0, 40):
            path.write_bytes(path.read_bytes()[:cut])
            self.assert_refused("train_positions.npy", False, "not a whole .npy array")

    def test_a_whole_dataset_reads(self):
        split = load_split(self.data, self.index, "train")
        self.assertEqual(split.images.shape, (24, 8, 16, 16))
        self.assertTrue(split.seen.all())


if __name__ == "__main__":
    unittest.main()
