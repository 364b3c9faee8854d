"""The pose head (issue 4): places the pelvis from the activity model's ConvLSTM state better
than the localiser's cluster position does, and exports it as a second ONNX model that the
classifier stage runs beside the activity model (docs/model_contract.md, "Pose head").

The activity model stays frozen: the head reads the state of the lane the classifier
predicts from, so it is fitted on the states after scans `--first-step`..T of training
windows (the histories the runtime's predicting lane has), with the localiser's position
in the image as a second input, to the pelvis's offset from that position. Needs a dataset
with `*_positions.npy` (`lidar-har dataset`, since session 22).

    PYTHONPATH=training training/.venv/bin/python -m lidar_har_train.pose_head \
        models/activity.onnx out/pose81 --out models/pose_head.onnx

Scores the pelvis error over the scans the localiser saw (median / p95, metres) on the test
splits, overall and per activity, before and after the head. The head is then used only for
the activities it helps on `test` (the drawn rooms' held-out episodes, as the classifier
reads them) and where the error it expects of itself (its second output, scaled on `test`)
is below the limit that does best there; `test_unseen` (a room never trained on) is the
figure to quote.
"""

import argparse
import hashlib
import sys
import time
from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch
from onnx import numpy_helper
from torch import nn

from .arguments import at_least, number
from .data import CLASSES, DatasetError, load_array, load_index, load_split
from .export import PARITY_TOLERANCE, ExportError, model_from_onnx, set_metadata
from .outputs import OutputError, prepare_output, replaced_when_done, report_json, set_aside
from .train import DeviceError, choose_device

KEY_ACTIVITY_SHA256 = "lidar_har.pose_head.activity_sha256"
KEY_MIN_HISTORY = "lidar_har.pose_head.min_history"
KEY_ACTIVITIES = "lidar_har.pose_head.activities"
KEY_MAX_SIGMA = "lidar_har.pose_head.max_sigma_m"


def features(model, split, positions, rows, first_step: int, device: torch.device):
    """For the scans the localiser saw at steps `first_step`.. of the windows `rows`: the
    ConvLSTM state `[n, hidden, s, s]` (float16, kept on `device`), the localiser's position
    from the image centre `[n, 2]`, the pelvis's offset from it `[n, 2]`, the true and the
    predicted activity `[n]` (numpy)."""
    seen = np.isfinite(positions[rows, first_step:]).all(axis=-1)
    # Filled in place: gathering the steps' states and joining them would need twice the memory.
    states = torch.empty((int(seen.sum()), model.hidden, model.state_size, model.state_size),
                         dtype=torch.float16, device=device)
    filled = 0
    located, offsets, labels, predicted = [], [], [], []
    with torch.no_grad():
        for start in range(0, len(rows), 512):
            batch = rows[start : start + 512]
            frames = torch.from_numpy(split.images[batch]).to(device).float() / 255.0
            h, c = model.zero_state(len(batch))
            for t in range(frames.shape[1]):
                logits, h, c = model.step(frames[:, t : t + 1], h, c)
                if t < first_step:
                    continue
                pos = positions[batch, t]
                keep = seen[start : start + 512, t - first_step]
                kept = h[torch.from_numpy(keep).to(device)]
                states[filled : filled + len(kept)] = kept
                filled += len(kept)
                located.append(pos[keep, 2:])
                offsets.append(pos[keep, :2] - pos[keep, 2:])
                labels.append(split.labels[batch, t][keep])
                predicted.append(logits.argmax(dim=1).cpu().numpy()[keep])
    return {"states": states, "located": np.concatenate(located).astype(np.float32),
            "offsets": np.concatenate(offsets).astype(np.float32), "labels": np.concatenate(labels),
            "predicted": np.concatenate(predicted)}


class PoseHead(nn.Module):
    """State and localiser position in; the pelvis's offset from the localiser and the head's
    own expected error (deviation per axis of a circular Gaussian, metres) out. The error is
    read from the offset's last hidden layer without training it: the offset is fitted as if
    the deviation were not there. `channels` and `units` size its convolution and hidden
    layer (32 and 64 in the committed head)."""

    def __init__(self, hidden: int, side: int, channels: int = 32, units: int = 64):
        super().__init__()
        self.conv = nn.Sequential(nn.Conv2d(hidden, channels, 3, padding=1), nn.ReLU())
        self.mlp = nn.Sequential(nn.Linear(channels * side * side + 2, units), nn.ReLU(), nn.Linear(units, 2))
        self.log_sigma = nn.Linear(units, 1)

    def forward(self, h, located):
        features = self.mlp[:2](torch.cat([self.conv(h).flatten(1), located], dim=1))
        return self.mlp[2](features), torch.exp(self.log_sigma(features.detach()))


def sigma_loss(sigma, error):
    """Negative log-likelihood of a circular Gaussian error of deviation `sigma` per axis, for
    the errors the offset made (detached, as are the features: the deviation learns how far
    off the offset is without changing it)."""
    return (2 * torch.log(sigma[:, 0]) + error.detach().pow(2).sum(dim=1) / (2 * sigma[:, 0] ** 2)).mean()


def tensors(data, rows, device: torch.device):
    """The head's inputs and target for the scans `rows` of `data`, on `device`."""
    states = data["states"][torch.from_numpy(rows).to(device)].float()
    return states, torch.from_numpy(data["located"][rows]).to(device), torch.from_numpy(data["offsets"][rows]).to(device)


def mean_error(head, data, rows, device: torch.device) -> float:
    """Mean pelvis error (metres) of the head over the scans `rows` of `data`."""
    total = 0.0
    with torch.no_grad():
        for b in range(0, len(rows), 8192):
            states, located, target = tensors(data, rows[b : b + 8192], device)
            total += float(torch.linalg.norm(head(states, located)[0] - target, dim=1).sum())
    return total / max(len(rows), 1)


def fit(head, data, minutes: float, seed: int, batch: int, lr: float, validation_fraction: float,
        beta: float, device: torch.device):
    """Adam for `minutes`, the rate decaying along a cosine to 1 % of `lr`. Keeps the weights
    of the epoch with the lowest mean error on `validation_fraction` of the scans (drawn
    from the training windows, at random: the scans of one window are correlated, so the
    figure watches for the fit running away rather than measuring the head). The offset's loss
    is smooth L1 with `beta`: small, it fits the median of an ambiguous pelvis (a body on
    the floor seen in part); large, the mean, which trades some median for a shorter tail."""
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(data["offsets"]))
    held = int(round(validation_fraction * len(order)))
    validation, train = np.sort(order[:held]), order[held:]
    optimiser = torch.optim.Adam(head.parameters(), lr=lr)
    best, best_state = np.inf, None
    start, epoch = time.time(), 0
    while time.time() - start < minutes * 60:
        total = 0.0
        for b in range(0, len(train), batch):
            progress = min((time.time() - start) / (minutes * 60), 1.0)
            for group in optimiser.param_groups:
                group["lr"] = lr * (0.01 + 0.99 * 0.5 * (1 + np.cos(np.pi * progress)))
            states, located, target = tensors(data, train[b : b + batch], device)
            pred, sigma = head(states, located)
            loss = nn.functional.smooth_l1_loss(pred, target, beta=beta) + sigma_loss(sigma, pred - target)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item() * len(target)
        rng.shuffle(train)
        epoch += 1
        report = f"epoch {epoch}: loss {total / len(train):.4f}"
        if held:
            error = mean_error(head, data, validation, device)
            if error < best:
                best, best_state = error, {k: v.detach().clone() for k, v in head.state_dict().items()}
            report += f", validation mean error {error:.4f} m (best {best:.4f})"
        print(f"{report} ({(time.time() - start) / 60:.1f} min)", flush=True)
    if best_state is not None:
        head.load_state_dict(best_state)


def predict(head, data, device: torch.device):
    """The head's offsets `[n, 2]` and deviations `[n]` for every scan of `data` (numpy)."""
    offsets, sigmas = [], []
    with torch.no_grad():
        for b in range(0, len(data["offsets"]), 8192):
            offset, sigma = head(data["states"][b : b + 8192].float(),
                                 torch.from_numpy(data["located"][b : b + 8192]).to(device))
            offsets.append(offset.cpu().numpy())
            sigmas.append(sigma.cpu().numpy()[:, 0])
    return np.concatenate(offsets), np.concatenate(sigmas)


def pair(errors):
    return [round(float(np.median(errors)), 3), round(float(np.percentile(errors, 95)), 3)] if len(errors) else None


def helped_activities(before, after, predicted) -> list[str]:
    """The activities, as the classifier reads them, whose mean pelvis error the head lowers
    (the mean weighs the tail as well as the middle: a head that halves the median but
    doubles the worst errors is not used)."""
    return [name for k, name in enumerate(CLASSES)
            if (predicted == k).sum() >= 100 and after[predicted == k].mean() < before[predicted == k].mean()]


def placed(data, sigma, used, max_sigma: float):
    """The scans on which the runtime places the pelvis with the head: read as an activity in
    `used`, with the head expecting an error of at most `max_sigma`."""
    return np.isin(data["predicted"], [CLASSES.index(n) for n in used]) & (sigma <= max_sigma)


def doubt_threshold(before, after, sigma, used_scans) -> float:
    """The deviation above which the localiser's position is kept instead of the head's: the
    one, among the deviations' percentiles, that gives the lowest mean error (infinite when
    trusting the head everywhere does best)."""
    candidates = [np.inf, *np.percentile(sigma[used_scans], np.arange(50, 100, 2))] if used_scans.any() else [np.inf]
    mean_error = [np.where(used_scans & (sigma <= t), after, before).mean() for t in candidates]
    return float(candidates[int(np.argmin(mean_error))])


def calibrate(head, error, sigma) -> float:
    """Scales the head's deviations so that half of `error` lies within the median radius of
    the Gaussian they describe (sigma * sqrt(2 ln 2)): fitted on its training scans, the head
    expects the smaller errors it made there. Folded into `log_sigma`'s bias, so the exported
    model outputs the scaled deviation; returns the scale."""
    scale = float(np.median(error / sigma)) / np.sqrt(2 * np.log(2))
    with torch.no_grad():
        head.log_sigma.bias += np.log(scale)
    return scale


def calibration(error, sigma) -> dict:
    """Share of errors within one and two deviations: 39 % and 86 % for a calibrated
    circular Gaussian."""
    return {f"within_{k}_sigma": round(float((error <= k * sigma).mean()), 3) for k in (1, 2)}


def scores(before, after, sigma, data, used, max_sigma):
    """Pelvis errors: the localiser alone, the head everywhere, the head where the runtime
    places it (what it publishes); overall and per true activity."""
    placed_scans = placed(data, sigma, used, max_sigma)
    gated = np.where(placed_scans, after, before)
    report = {"scans": int(len(before)), "placed": round(float(placed_scans.mean()), 3),
              "calibration": calibration(after, sigma)}
    for name, errors in (("localiser", before), ("head", after), ("published", gated)):
        report[name] = {"median_p95_m": pair(errors),
                        "per_activity": {c: pair(errors[data["labels"] == k]) for k, c in enumerate(CLASSES)}}
    return report


def export(head, out: Path, hidden: int, side: int, metadata: dict, sample: dict):
    """Writes the head as ONNX (`h` [1, hidden, side, side], `located` [1, 2] -> `offset`
    [1, 2], `sigma` [1, 1]) with `metadata`, checked against PyTorch on `sample`; the head
    is moved to the CPU. Written under a temporary name, renamed to `out` once it passed: a
    failed check leaves what was at `out` (the refused head is kept beside it)."""
    head.cpu().eval()
    with replaced_when_done(out) as temp:
        torch.onnx.export(head, (torch.rand(1, hidden, side, side), torch.rand(1, 2)), str(temp),
                          input_names=["h", "located"], output_names=["offset", "sigma"], opset_version=18,
                          dynamo=False)
        proto = onnx.load(str(temp))
        set_metadata(proto, metadata,
                     "lidar_har pose head: pelvis offset from the activity model's state (docs/model_contract.md)")
        onnx.checker.check_model(proto)
        onnx.save(proto, str(temp))
        session = ort.InferenceSession(str(temp), providers=["CPUExecutionProvider"])
        worst = 0.0
        with torch.no_grad():
            for i in range(len(sample["states"])):
                h = sample["states"][i : i + 1].float().cpu().numpy()
                located = sample["located"][i : i + 1]
                reference = head.double()(torch.from_numpy(h).double(), torch.from_numpy(located).double())
                got = session.run(["offset", "sigma"], {"h": h, "located": located})
                for r, g in zip(reference, got):
                    # np.maximum keeps a NaN, which must fail the check (max(0.0, nan) is 0.0).
                    worst = float(np.maximum(worst, np.abs(r.numpy() - g).max()))
        head.float()
        if not worst <= PARITY_TOLERANCE:
            rejected = set_aside(temp, out)
            raise ExportError(f"pose head parity check failed: {worst:.2e} > {PARITY_TOLERANCE:.0e}; "
                              f"{out} is not written, the refused head is {rejected}")
    return worst


def load_head(path: Path, hidden: int, side: int) -> PoseHead:
    """A head exported by this script, with its weights (to score or gate it again); its
    width is read from the weights."""
    weights = {i.name: numpy_helper.to_array(i) for i in onnx.load(str(path)).graph.initializer}
    width = {k: weights[k].shape[0] for k in ("conv.0.weight", "mlp.0.weight") if k in weights}
    head = PoseHead(hidden, side, width.get("conv.0.weight", 32), width.get("mlp.0.weight", 64))
    state = head.state_dict()
    missing = [k for k in state if k not in weights or weights[k].shape != tuple(state[k].shape)]
    if missing:
        raise ExportError(f"{path}: not a pose head for this model (weights missing or of another shape: {missing})")
    head.load_state_dict({k: torch.from_numpy(weights[k].copy()) for k in state})
    return head


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("model", type=Path, help="the activity step model (ONNX) whose state the head reads")
    parser.add_argument("data", type=Path, help="a dataset with *_positions.npy")
    parser.add_argument("--out", type=Path, help="where to write the head (ONNX)")
    parser.add_argument("--head", type=Path, help="score (and gate, with --out) this exported head instead of fitting one")
    parser.add_argument("--init-from", type=Path, help="start the fit from this exported head's weights (its size)")
    parser.add_argument("--train-windows", type=at_least(0), default=0,
                        help="fit on this many training windows (0: all)")
    parser.add_argument("--test-windows", type=at_least(0), default=0,
                        help="score on this many windows per test split (0: all)")
    parser.add_argument("--first-step", type=at_least(0), default=11,
                        help="first step (0-based) of each window fitted on: history first_step + 1")
    parser.add_argument("--minutes", type=number(above=0), default=25.0)
    parser.add_argument("--batch", type=at_least(1), default=256)
    parser.add_argument("--lr", type=number(above=0), default=1e-3,
                        help="Adam's first rate; decays to 1 %% of it along a cosine")
    parser.add_argument("--beta", type=number(minimum=0), default=0.05,
                        help="smooth L1's beta (m) for the offset: quadratic below it, linear above")
    parser.add_argument("--validation-fraction", type=number(minimum=0, below=1), default=0.02,
                        help="training scans held out to keep the best epoch's weights (0: keep the last)")
    parser.add_argument("--channels", type=at_least(1), default=32, help="the head's convolution channels")
    parser.add_argument("--units", type=at_least(1), default=64, help="the head's hidden units")
    parser.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto",
                        help="where the states are kept and the head fitted (auto: a CUDA GPU when PyTorch sees one)")
    parser.add_argument("--threads", type=at_least(1), default=2)
    parser.add_argument("--seed", type=at_least(0), default=1)
    parser.add_argument("--json", type=Path, help="write the scores here")
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    try:
        return run(args)
    except (DatasetError, DeviceError, ExportError, OutputError) as err:
        print(f"pose_head: error: {err}", file=sys.stderr)
        return 1


def run(args) -> int:
    device = choose_device(args.device)
    # Checked before the minutes of state extraction and fitting, not after them.
    for path in (args.out, args.json):
        if path:
            prepare_output(path)
    torch.set_num_threads(args.threads)
    torch.manual_seed(args.seed)
    index = load_index(args.data)
    window = index["spec"]["window"]
    if args.first_step >= window:
        raise DatasetError(f"--first-step {args.first_step}: the windows of {args.data} have {window} scans "
                           f"(steps 0..{window - 1})")
    model = model_from_onnx(args.model, index["spec"]).to(device)
    data = {}
    # Every split checked before any is read: extracting the states takes minutes per split.
    # A dataset made without `--held-out` has no unseen room to score.
    splits = [name for name in (("test", "test_unseen") if args.head else ("train", "test", "test_unseen"))
              if name != "test_unseen" or index["splits"].get(name, {}).get("windows", 0) > 0]
    for name in splits:
        info = index["splits"].get(name, {})
        if info.get("windows", 0) == 0:
            raise DatasetError(f"{args.data}: split {name} has no windows")
        if "positions" not in info:
            raise DatasetError(f"{args.data}: no positions in split {name}; remake it with today's `lidar-har dataset`")
    for name in splits:
        split = load_split(args.data, index, name, mapped=True)
        info = index["splits"][name]
        positions = load_array(args.data / info["positions"])
        rows = np.arange(len(split))
        limit = args.train_windows if name == "train" else args.test_windows
        if 0 < limit < len(rows):
            rows = np.sort(np.random.default_rng(args.seed).choice(rows, limit, replace=False))
        data[name] = features(model, split, positions, rows, args.first_step, device)
        print(f"{name}: {len(data[name]['states'])} seen scans from {len(rows)} windows", flush=True)
    if args.head:
        head = load_head(args.head, model.hidden, model.state_size).to(device)
    else:
        head = (load_head(args.init_from, model.hidden, model.state_size) if args.init_from
                else PoseHead(model.hidden, model.state_size, args.channels, args.units)).to(device)
        print(f"fitting on {device}: {sum(p.numel() for p in head.parameters())} parameters", flush=True)
        fit(head, data["train"], args.minutes, args.seed, args.batch, args.lr, args.validation_fraction, args.beta, device)
    errors = {}
    for name in splits:
        offsets, sigma = predict(head, data[name], device)
        before = np.linalg.norm(data[name]["offsets"], axis=1)
        after = np.linalg.norm(data[name]["offsets"] - offsets, axis=1)
        errors[name] = (before, after, sigma)
    before, after, sigma = errors["test"]
    used = helped_activities(before, after, data["test"]["predicted"])
    scale = calibrate(head, after, sigma)
    errors = {name: (b, a, s * scale) for name, (b, a, s) in errors.items()}
    before, after, sigma = errors["test"]
    max_sigma = doubt_threshold(before, after, sigma, placed(data["test"], sigma, used, np.inf))
    report = {"activities": used, "max_sigma_m": max_sigma if np.isfinite(max_sigma) else None,
              "sigma_scale": round(scale, 3),
              "first_step": args.first_step,
              "head": {"channels": head.conv[0].out_channels, "units": head.mlp[0].out_features},
              "train_windows": 0 if args.head else args.train_windows,
              "fit": None if args.head else {
                  "device": str(device), "minutes": args.minutes, "batch": args.batch, "lr": args.lr,
                  "validation_fraction": args.validation_fraction, "beta": args.beta, "seed": args.seed,
                  "init_from": str(args.init_from) if args.init_from else None}}
    for name, (before, after, sigma) in errors.items():
        report[name] = scores(before, after, sigma, data[name], used, max_sigma)
        r = report[name]
        print(f"{name}: localiser {r['localiser']['median_p95_m']}, head {r['head']['median_p95_m']}, "
              f"published {r['published']['median_p95_m']} (median, p95 m; placed on {r['placed']:.1%}; "
              f"errors within 1 / 2 sigma: {r['calibration']['within_1_sigma']:.1%} / "
              f"{r['calibration']['within_2_sigma']:.1%}, 39 % / 86 % if calibrated)")
        for c in CLASSES:
            print(f"    {c:20s} {r['localiser']['per_activity'][c]} -> {r['head']['per_activity'][c]}"
                  f" -> {r['published']['per_activity'][c]}")
    print(f"head used for: {', '.join(used)}; where it expects an error of at most {max_sigma:.3f} m per axis")
    # The scores first: a failed export must not lose them.
    write_report(args.json, report)
    if args.out:
        metadata = head_metadata(args.model, args.first_step, used, max_sigma)
        sample = {k: v[:200] for k, v in data["test"].items()}
        worst = export(head, args.out, model.hidden, model.state_size, metadata, sample)
        report["parity_max_abs_diff"] = worst
        print(f"wrote {args.out} (parity with PyTorch: max abs difference {worst:.1e})")
        write_report(args.json, report)
    return 0


def head_metadata(model: Path, first_step: int, used: list[str], max_sigma: float) -> dict:
    """The rules of the head's use, for the runtime (docs/model_contract.md, "Pose head").
    `max_sigma` at full precision (`repr`, "inf" without a limit): rounded, the runtime's
    gate would differ from the one the head was scored with, for the expected errors between
    the two."""
    return {
        KEY_ACTIVITY_SHA256: hashlib.sha256(model.read_bytes()).hexdigest(),
        KEY_MIN_HISTORY: str(first_step + 1),
        KEY_ACTIVITIES: ",".join(used),
        KEY_MAX_SIGMA: repr(max_sigma),
    }


def write_report(path: Path | None, report: dict) -> None:
    """As train.py writes its report: a non-finite figure (a score over no scans) as null,
    not as a bare `NaN`, which is no JSON."""
    if path:
        path.write_text(report_json(report))


if __name__ == "__main__":
    sys.exit(main())
