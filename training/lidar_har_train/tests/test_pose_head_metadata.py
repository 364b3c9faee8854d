"""The rules of the pose head's use as its model carries them. Runs without PyTorch too."""

import hashlib
import tempfile
import unittest
from pathlib import Path

from .stand_ins import import_command


class Metadata(unittest.TestCase):
    def test_the_runtime_gates_at_the_limit_the_head_was_scored_with(self):
        pose_head = import_command(self, "pose_head")
        with tempfile.TemporaryDirectory() as folder:
            model = Path(folder) / "activity.onnx"
            model.write_bytes(b"an activity model")
            max_sigma = 0.123456789
            metadata = pose_head.head_metadata(model, 11, ["lying_down", "sitting_on_floor"], max_sigma)
            unlimited = pose_head.head_metadata(model, 11, [], float("inf"))
        self.assertEqual(metadata[pose_head.KEY_ACTIVITY_SHA256], hashlib.sha256(b"an activity model").hexdigest())
        self.assertEqual(metadata[pose_head.KEY_MIN_HISTORY], "12")
        self.assertEqual(metadata[pose_head.KEY_ACTIVITIES], "lying_down,sitting_on_floor")
        # The runtime (crates/core/src/pose_head.rs) reads the text as an f64 and places where
        # sigma <= it. Written as 0.1235, it placed a sigma of 0.12346, which the scores counted
        # as the localiser's position.
        limit = float(metadata[pose_head.KEY_MAX_SIGMA])
        self.assertEqual(limit, max_sigma)
        self.assertFalse(0.12346 <= limit)
        self.assertEqual(unlimited[pose_head.KEY_MAX_SIGMA], "inf")


if __name__ == "__main__":
    unittest.main()
