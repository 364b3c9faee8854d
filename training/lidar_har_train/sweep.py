"""Accuracy against run time: trains and evaluates one model per configuration of a sweep file.

    python -m lidar_har_train.sweep --config training/sweep.toml --out out/sweep

Every configuration gets the same data budget (episodes, seeds, scenes) and the same number of
training steps, so the comparison is fair even though each model is undertrained compared with
the committed one. For each: `lidar-har dataset` (shared by configurations with the same image
settings), training and ONNX export (`lidar_har_train.train`), `lidar-har evaluate`. Results are
appended to `sweep.json` after each configuration (a cut-short sweep keeps what it measured),
then `sweep.md` (table, Pareto front) and `sweep.png` (accuracy against per-scan time).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import re
import subprocess
import sys
import time
import tomllib
from pathlib import Path

DATASET_KEYS = ("representation", "framing", "size", "resolution", "window", "fixed_lidar")
MODEL_KEYS = ("hidden", "encoder_channels")


class SweepError(Exception):
    pass


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", type=Path, required=True, help="sweep TOML file (training/sweep.toml)")
    p.add_argument("--out", type=Path, required=True, help="output directory")
    p.add_argument("--lidar-har", type=Path, default=Path("target/release/lidar-har"),
                   help="the lidar-har binary (cargo build --release --bin lidar-har)")
    p.add_argument("--only", nargs="*", default=None,
                   help="run only these configurations (names of training/sweep.toml's runs)")
    p.add_argument("--report-only", action="store_true", help="redraw sweep.md/png from sweep.json")
    p.add_argument("--retime", action="store_true",
                   help="re-measure every model's per-scan time with the classify benchmark, one after "
                        "another (the times measured during the sweep depend on what else ran), then redraw")
    return p.parse_args(argv)


def load_config(path: Path) -> tuple[dict, list[dict]]:
    try:
        config = tomllib.loads(path.read_text())
    except (OSError, tomllib.TOMLDecodeError) as err:
        raise SweepError(f"{path}: {err}") from err
    common, runs = config.get("common"), config.get("run")
    if not isinstance(common, dict) or not isinstance(runs, list) or not runs:
        raise SweepError(f"{path}: needs a [common] table and at least one [[run]]")
    base = {**common.get("dataset", {}), **common.get("model", {})}
    resolved = []
    for i, run in enumerate(runs):
        name = run.get("name")
        if not name:
            raise SweepError(f"{path}: run {i} has no name")
        unknown = set(run) - {"name", "why", *DATASET_KEYS, *MODEL_KEYS}
        if unknown:
            raise SweepError(f"{path}: run '{name}': unknown keys {sorted(unknown)}")
        settings = {**base, **{k: v for k, v in run.items() if k in DATASET_KEYS + MODEL_KEYS}}
        missing = [k for k in DATASET_KEYS + MODEL_KEYS if k not in settings]
        if missing:
            raise SweepError(f"{path}: run '{name}': no value for {missing} (in the run or [common])")
        resolved.append({"name": name, "why": run.get("why", ""), **settings})
    return common, resolved


def sh(cmd: list[str], log: Path) -> None:
    print("  $ " + " ".join(cmd), flush=True)
    with log.open("a") as out:
        out.write("$ " + " ".join(cmd) + "\n")
        out.flush()
        code = subprocess.run(cmd, stdout=out, stderr=subprocess.STDOUT).returncode
    if code != 0:
        raise SweepError(f"command failed with exit code {code} (log: {log}): {' '.join(cmd)}")


def dataset_for(run: dict, common: dict, args, log: Path) -> Path:
    key = json.dumps({k: run[k] for k in DATASET_KEYS}, sort_keys=True)
    key += json.dumps({k: common[k] for k in ("scenes", "held_out", "episodes", "episode_seconds", "seed")},
                      sort_keys=True)
    data = args.out / "data" / hashlib.sha1(key.encode()).hexdigest()[:12]
    if (data / "index.json").exists():
        return data
    cmd = [str(args.lidar_har), "dataset", "--scenes", common["scenes"], "--episodes", str(common["episodes"]),
           "--episode-seconds", str(common["episode_seconds"]), "--seed", str(common["seed"]),
           "--representation", run["representation"], "--framing", run["framing"],
           "--size", str(run["size"]), "--resolution", str(run["resolution"]), "--window", str(run["window"]),
           "--out", str(data)]
    for scene in common.get("held_out", []):
        cmd += ["--held-out", scene]
    if run["fixed_lidar"]:
        cmd.append("--fixed-lidar")
    sh(cmd, log)
    return data


def check_only(only: list[str] | None, runs: list[dict]) -> None:
    """`--only` must name configurations of the sweep: a misspelt name ran nothing and the
    sweep reported success."""
    if only is None:
        return
    known = [run["name"] for run in runs]
    if not only:
        raise SweepError(f"--only: give at least one configuration (known: {', '.join(known)})")
    unknown = [name for name in only if name not in known]
    if unknown:
        raise SweepError(f"--only: no configuration named {', '.join(unknown)} (known: {', '.join(known)})")


def run_one(run: dict, common: dict, args) -> dict:
    # Imported here: training needs PyTorch, the rest of the sweep (and its checks) does not.
    from . import train as train_module

    folder = args.out / run["name"]
    folder.mkdir(parents=True, exist_ok=True)
    log = folder / "log.txt"
    data = dataset_for(run, common, args, log)
    model = folder / "model.onnx"
    started = time.monotonic()
    train_args = ["--data", str(data), "--out", str(model), "--hidden", str(run["hidden"]),
                  "--encoder-channels", str(run["encoder_channels"]), "--batch", str(common["batch"]),
                  "--steps-per-epoch", str(common["steps_per_epoch"]), "--max-epochs", str(common["epochs"]),
                  "--patience", str(common["epochs"]), "--time-budget-min", "1000",
                  "--lr", str(common.get("lr", 3e-3)), "--lr-final", str(common.get("lr_final", 1e-4)),
                  "--val-fraction", "0.08", "--threads", str(common["threads"]), "--skip-test-eval"]
    print("  $ python -m lidar_har_train.train " + " ".join(train_args), flush=True)
    with log.open("a") as out:
        saved = sys.stdout
        sys.stdout = out
        try:
            code = train_module.train(train_module.parse_args(train_args))
        except (train_module.DatasetError, train_module.ExportError, train_module.OutputError) as err:
            print(f"train: error: {err}", file=out)
            code = 1
        finally:
            sys.stdout = saved
    if code != 0:
        raise SweepError(f"training '{run['name']}' failed (log: {log})")
    train_s = time.monotonic() - started
    evaluation = folder / "eval"
    sh([str(args.lidar_har), "evaluate", "--model", str(model), "--data", str(data), "--out", str(evaluation)], log)
    metrics = json.loads((evaluation / "metrics.json").read_text())
    training = json.loads(model.with_suffix(".training.json").read_text())
    unseen = metrics["splits"].get("test_unseen", {})
    return {
        **run,
        "data": str(data),
        "parameters": training["parameters"],
        "train_minutes": round(train_s / 60, 1),
        "accuracy": metrics["accuracy"],
        "unseen_accuracy": unseen.get("accuracy"),
        "macro_f1": metrics["macro_f1"],
        "fall_recall": metrics["recall"]["falling_down"],
        "running_recall": metrics["recall"]["running"],
        "step_ms": metrics["step_ms_mean"],
        # Streaming runs two staggered lanes, so a scan costs two model steps.
        "scan_ms": 2 * metrics["step_ms_mean"],
        "per_episode": metrics.get("per_episode"),
    }


def retime(results: list[dict], out: Path) -> None:
    """Per-scan time (render + two steps + softmax, one thread) from `cargo bench ... classify`."""
    for r in results:
        model = out / r["name"] / "model.onnx"
        cmd = ["cargo", "bench", "-q", "-p", "lidar-har-infer", "--bench", "classify", "--locked", "--", str(model.resolve())]
        print("  $ " + " ".join(cmd), flush=True)
        run = subprocess.run(cmd, capture_output=True, text=True)
        found = re.search(r"per scan .*?: ([0-9.]+) ms", run.stdout)
        if run.returncode != 0 or not found:
            raise SweepError(f"timing {model} failed (exit {run.returncode}): {run.stderr[-500:]}")
        r.setdefault("scan_ms_during_sweep", r["scan_ms"])
        r["scan_ms"] = float(found.group(1))
        r["timed_by"] = "cargo bench -p lidar-har-infer --bench classify"


def pareto(results: list[dict]) -> set[str]:
    """Names of the results no other result beats on both accuracy and per-scan time."""
    front = set()
    for r in results:
        if r.get("fixed_lidar"):
            continue
        dominated = any(o is not r and not o.get("fixed_lidar") and o["accuracy"] >= r["accuracy"]
                        and o["scan_ms"] <= r["scan_ms"]
                        and (o["accuracy"] > r["accuracy"] or o["scan_ms"] < r["scan_ms"]) for o in results)
        if not dominated:
            front.add(r["name"])
    return front


def stale_rows(results: list[dict], common: dict, names: list[str], failed: list[str]) -> dict[str, str]:
    """Why each stored result that this sweep's settings would not give is shown, by name."""
    stale = {}
    for r in results:
        if r["name"] not in names:
            stale[r["name"]] = "no longer in sweep.toml"
        elif r["name"] in failed:
            stale[r["name"]] = "failed in this sweep; an earlier run's result"
        elif r.get("common") != common:
            stale[r["name"]] = "run with other [common] settings" if "common" in r else "its [common] settings unrecorded"
    return stale


def write_report(results: list[dict], common: dict, out: Path, stale: dict[str, str]) -> None:
    front = pareto([r for r in results if r["name"] not in stale])
    pct = lambda x: "-" if x is None else f"{100 * x:.1f}"  # noqa: E731
    if all(r.get("timed_by") for r in results):
        timing = ("Per-scan time: rendering, two model steps (streaming runs two staggered lanes) and softmax, "
                  "one thread, re-measured for all models one after another (`training/sweep.sh --retime`). ")
    elif any(r.get("timed_by") for r in results):
        timing = ("Per-scan time: MIXED, the rows' times are not comparable: some re-measured with the classify "
                  "benchmark, the others (" + ", ".join(r["name"] for r in results if not r.get("timed_by"))
                  + ") measured by `lidar-har evaluate` while the sweep ran; `training/sweep.sh --retime` "
                  "re-measures all. ")
    else:
        timing = ("Per-scan time: two model steps (streaming runs two staggered lanes), one ONNX Runtime thread, "
                  "measured by `lidar-har evaluate` while the sweep ran (noisy: `--retime` re-measures). ")
    lines = [
        "# Accuracy against run time",
        "",
        f"Each configuration: {common['episodes']} episodes of {common['episode_seconds']} s over "
        f"`{common['scenes']}` (held out: {', '.join(common.get('held_out', [])) or 'none'}), seed {common['seed']}; "
        f"{common['epochs'] * common['steps_per_epoch']} training steps of {common['batch']} windows. "
        + timing +
        "`*`: on the Pareto front (no other moving-robot configuration is both more accurate and faster).",
        "",
        "| configuration | representation | framing | px | m/px | T | hidden | params | test % | unseen % "
        "| fall recall % | running recall % | ms/scan | time vs first |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    base_ms = results[0]["scan_ms"] if results else 1.0
    for r in results:
        mark = (" *" if r["name"] in front else "") + (" †" if r["name"] in stale else "")
        lines.append(
            f"| {r['name']}{mark} | {r['representation']} | {r['framing']}{' (fixed Lidar)' if r['fixed_lidar'] else ''} "
            f"| {r['size']} | {r['resolution']} | {r['window']} | {r['hidden']} | {r['parameters']} "
            f"| {pct(r['accuracy'])} | {pct(r['unseen_accuracy'])} | {pct(r['fall_recall'])} "
            f"| {pct(r['running_recall'])} | {r['scan_ms']:.3f} | {r['scan_ms'] / base_ms:.2f} |")
    if stale:
        lines += ["", "† Not this sweep's result: " + "; ".join(f"`{n}` {why}" for n, why in stale.items())
                  + " (`training/sweep.sh --only NAME` runs one again)."]
    for r in results:
        spread = r.get("per_episode")
        if r["fixed_lidar"] and spread:
            lines += ["", f"Fixed Lidar (`{r['name']}`), per test episode (one random spot each): best "
                      f"{pct(spread['best']['accuracy'])} % at {spread['best'].get('fixed_lidar_at')} in "
                      f"{spread['best']['scene']}, median {pct(spread['median'])} %, worst "
                      f"{pct(spread['worst']['accuracy'])} % at {spread['worst'].get('fixed_lidar_at')} in "
                      f"{spread['worst']['scene']} ({spread['episodes']} episodes). Paper: 82.9 % best, 74.0 % worst."]
    lines += ["", "Why each configuration is in the sweep:", ""]
    lines += [f"- `{r['name']}`: {r['why']}" for r in results if r.get("why")]
    (out / "sweep.md").write_text("\n".join(lines) + "\n")
    plot(results, front, out / "sweep.png")


def plot(results: list[dict], front: set[str], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.5), dpi=120)
    for r in results:
        colour = "tab:red" if r["name"] in front else ("tab:gray" if r["fixed_lidar"] else "tab:blue")
        ax.scatter(r["scan_ms"], 100 * r["accuracy"], color=colour)
        ax.annotate(r["name"], (r["scan_ms"], 100 * r["accuracy"]), fontsize=7, xytext=(4, 3),
                    textcoords="offset points")
    line = sorted((r for r in results if r["name"] in front), key=lambda r: r["scan_ms"])
    ax.plot([r["scan_ms"] for r in line], [100 * r["accuracy"] for r in line], color="tab:red", lw=1)
    ax.set_xlabel("inference per scan, ms (two model steps, 1 thread)")
    ax.set_ylabel("test accuracy, %")
    ax.set_title("Activity recognition: accuracy against run time (red: Pareto front)")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        common, runs = load_config(args.config)
        check_only(args.only, runs)
        args.out.mkdir(parents=True, exist_ok=True)
        results_path = args.out / "sweep.json"
        results = json.loads(results_path.read_text()) if results_path.exists() else []
        failed = []
        # Configurations whose run failed: a result stored for them is an earlier run's.
        not_run = []
        if args.retime:
            retime(results, args.out)
            results_path.write_text(json.dumps(results, indent=2) + "\n")
        elif not args.report_only:
            if not args.lidar_har.exists():
                raise SweepError(f"--lidar-har {args.lidar_har}: not found (cargo build --release --bin lidar-har)")
            for run in runs:
                if args.only is not None and run["name"] not in args.only:
                    continue
                print(f"sweep: {run['name']}", flush=True)
                try:
                    result = run_one(run, common, args)
                except SweepError as err:
                    # One failed configuration must not cost the rest of a three-hour sweep.
                    print(f"sweep: {run['name']} failed, going on: {err}", file=sys.stderr, flush=True)
                    failed.append(run["name"])
                    not_run.append(run["name"])
                    continue
                result["common"] = common
                # After `--retime`, a configuration run again is retimed too: one table must not
                # put the benchmark's times beside those measured during the sweep.
                if any(r.get("timed_by") for r in results if r["name"] != run["name"]):
                    try:
                        retime([result], args.out)
                    except SweepError as err:
                        # Kept with the time measured during the sweep; sweep.md names such rows.
                        print(f"sweep: {run['name']}: {err}", file=sys.stderr, flush=True)
                        failed.append(run["name"])
                results = [r for r in results if r["name"] != run["name"]] + [result]
                order = [r["name"] for r in runs]
                results.sort(key=lambda r: order.index(r["name"]) if r["name"] in order else len(order))
                results_path.write_text(json.dumps(results, indent=2) + "\n")
                print(f"  accuracy {100 * result['accuracy']:.1f} %, {result['scan_ms']:.3f} ms/scan", flush=True)
        stale = stale_rows(results, common, [r["name"] for r in runs], not_run)
        write_report(results, common, args.out, stale)
        print(f"sweep: wrote {args.out / 'sweep.md'} and {args.out / 'sweep.png'}")
        if failed:
            print(f"sweep: failed configurations (see their log.txt): {', '.join(failed)}", file=sys.stderr)
            return 1
        return 0
    except SweepError as err:
        print(f"sweep: error: {err}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
