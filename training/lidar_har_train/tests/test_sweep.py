import io
import json
import sys
import tempfile
import unittest
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from unittest import mock

from lidar_har_train import sweep

ROOT = Path(__file__).resolve().parents[3]
RETIMED_BY = "cargo bench -p lidar-har-infer --bench classify"


def row(name: str, scan_ms: float, retimed: bool) -> dict:
    """A sweep.json row as run_one writes it (and `retime` then marks)."""
    r = {"name": name, "why": "", "representation": "boolean_grid", "framing": "person_centred", "size": 32,
         "resolution": 0.08, "window": 20, "fixed_lidar": False, "hidden": 16, "encoder_channels": 8,
         "parameters": 14849, "train_minutes": 1.0, "accuracy": 0.6, "unseen_accuracy": 0.5, "macro_f1": 0.5,
         "fall_recall": 0.3, "running_recall": 0.7, "step_ms": scan_ms / 2, "scan_ms": scan_ms,
         "per_episode": None}
    if retimed:
        r.update(scan_ms_during_sweep=scan_ms, scan_ms=0.1, timed_by=RETIMED_BY)
    return r


class OnlyAfterRetime(unittest.TestCase):
    """`sweep.sh --only NAME` after `--retime`: the configuration run again is retimed too, so
    sweep.md never puts evaluate's times beside the benchmark's under the benchmark's label."""

    def run_sweep(self, out: Path, retime):
        def run_one(run, common, args):
            return row(run["name"], 0.3, retimed=False)

        stdout, stderr = io.StringIO(), io.StringIO()
        with mock.patch.object(sweep, "run_one", run_one), mock.patch.object(sweep, "retime", retime), \
                mock.patch.object(sweep, "plot", lambda *a: None), redirect_stdout(stdout), redirect_stderr(stderr):
            code = sweep.main(["--config", str(ROOT / "training/sweep.toml"), "--out", str(out),
                               "--lidar-har", sys.executable, "--only", "narrow"])
        return code, stderr.getvalue()

    def test_a_run_again_configuration_is_retimed_when_the_others_are(self):
        retimed = []

        def retime(results, out):
            for r in results:
                retimed.append(r["name"])
                r.update(scan_ms_during_sweep=r["scan_ms"], scan_ms=0.08, timed_by=RETIMED_BY)

        with tempfile.TemporaryDirectory() as d:
            out = Path(d)
            (out / "sweep.json").write_text(json.dumps([row("reference", 0.2, True), row("narrow", 0.2, True)]))
            code, stderr = self.run_sweep(out, retime)
            self.assertEqual(code, 0, stderr)
            self.assertEqual(retimed, ["narrow"])
            results = json.loads((out / "sweep.json").read_text())
            self.assertTrue(all(r.get("timed_by") for r in results), results)
            self.assertEqual(results[1]["scan_ms"], 0.08)
            self.assertIn("re-measured for all models", (out / "sweep.md").read_text())

    def test_a_sweep_never_retimed_is_left_alone(self):
        def retime(results, out):
            self.fail(f"retimed {[r['name'] for r in results]}")

        with tempfile.TemporaryDirectory() as d:
            out = Path(d)
            (out / "sweep.json").write_text(json.dumps([row("reference", 0.2, False)]))
            code, stderr = self.run_sweep(out, retime)
            self.assertEqual(code, 0, stderr)
            self.assertIn("measured by `lidar-har evaluate` while the sweep ran", (out / "sweep.md").read_text())

    def test_a_failed_retiming_keeps_the_result_and_says_the_table_mixes_timings(self):
        def retime(results, out):
            raise sweep.SweepError("timing narrow failed (exit 101)")

        with tempfile.TemporaryDirectory() as d:
            out = Path(d)
            (out / "sweep.json").write_text(json.dumps([row("reference", 0.2, True)]))
            code, stderr = self.run_sweep(out, retime)
            self.assertEqual(code, 1)
            self.assertIn("sweep: narrow: timing narrow failed", stderr)
            results = json.loads((out / "sweep.json").read_text())
            self.assertEqual([r["name"] for r in results], ["reference", "narrow"])
            report = (out / "sweep.md").read_text()
            self.assertIn("MIXED", report)
            self.assertIn("the others (narrow) measured by `lidar-har evaluate`", report)


class StaleRows(unittest.TestCase):
    """Stored results this sweep would not give (a configuration that failed now, one gone from
    sweep.toml, one run with other [common] settings) are marked, not shown as current."""

    def test_results_not_from_this_sweep_are_marked_and_kept_off_the_front(self):
        common, _ = sweep.load_config(ROOT / "training/sweep.toml")

        def run_one(run, common, args):
            raise sweep.SweepError("dataset failed (exit 101)")

        current = dict(row("reference", 0.2, False), common=common)
        other = dict(common, seed=common["seed"] + 1)
        stored = [current, dict(row("narrow", 0.1, False), common=common, accuracy=0.9),
                  dict(row("wide", 0.1, False), common=other, accuracy=0.9), row("gone", 0.1, False)]
        with tempfile.TemporaryDirectory() as d:
            out = Path(d)
            (out / "sweep.json").write_text(json.dumps(stored))
            with mock.patch.object(sweep, "run_one", run_one), mock.patch.object(sweep, "plot", lambda *a: None), \
                    redirect_stdout(io.StringIO()), redirect_stderr(io.StringIO()):
                code = sweep.main(["--config", str(ROOT / "training/sweep.toml"), "--out", str(out),
                                   "--lidar-har", sys.executable, "--only", "narrow"])
            self.assertEqual(code, 1)
            report = (out / "sweep.md").read_text()
            self.assertIn("| reference * |", report)
            for name in ["narrow", "wide", "gone"]:
                self.assertIn(f"| {name} † |", report)
            self.assertIn("`narrow` failed in this sweep; an earlier run's result", report)
            self.assertIn("`wide` run with other [common] settings", report)
            self.assertIn("`gone` no longer in sweep.toml", report)


if __name__ == "__main__":
    unittest.main()
