"""Trains the activity ConvLSTM on a `lidar-har dataset` directory and exports the ONNX step model.

    python -m lidar_har_train.train --data DIR --out models/activity.onnx

Loss: cross-entropy at every step from T/2 on (docs/model_contract.md), each step against the
activity at that step's scan. Class balance: windows are drawn with probability inversely
proportional to their class's count (by the window's last label). Early stopping on a
validation split made of whole training episodes. Augmentation: the eight rotations/flips of
the square image (the map frame has no preferred direction for a person), and small shifts
(the localiser's position error).
"""

from __future__ import annotations

import math
import os
import random
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

import numpy as np
import torch
from torch import nn

from .data import CLASSES, DatasetError, Split, load_index, load_split
from .export import ExportError, export_step_model, model_from_onnx
from .model import ActivityConvLSTM
from .outputs import OutputError, prepare_output, report_json
from .train_args import parse_args


class DeviceError(Exception):
    pass


def choose_device(name: str) -> torch.device:
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise DeviceError("--device cuda: PyTorch sees no CUDA GPU (torch.cuda.is_available() is false)")
    return torch.device(name)


def seed_everything(seed: int, threads: int, device: torch.device):
    random.seed(seed)
    np.random.seed(seed)
    torch.manual_seed(seed)
    torch.set_num_threads(threads)
    if device.type == "cuda":
        # cuBLAS needs this workspace setting for deterministic results; without it, the
        # deterministic mode below refuses matrix products on the GPU.
        os.environ.setdefault("CUBLAS_WORKSPACE_CONFIG", ":4096:8")
    torch.use_deterministic_algorithms(True)


def split_validation(train: Split, fraction: float, rng: np.random.Generator) -> tuple[Split, Split]:
    """Holds out whole episodes (never single windows) for validation."""
    episodes = np.unique(train.episodes)
    if len(episodes) < 2:
        raise DatasetError("the train split has fewer than 2 episodes: cannot hold any out for validation")
    # At least one episode on each side, whatever the fraction rounds to.
    count = min(max(1, int(round(fraction * len(episodes)))), len(episodes) - 1)
    held = rng.choice(episodes, size=count, replace=False)
    mask = np.isin(train.episodes, held)
    return train.subset(~mask, "train"), train.subset(mask, "validation")


def to_tensor(images: np.ndarray, device: torch.device = torch.device("cpu")) -> torch.Tensor:
    """uint8 windows to float in [0, 1]; the bytes travel to the device before the conversion."""
    return torch.from_numpy(images).to(device).float() / 255.0


def shift(window: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """Moves every frame of `[T, S, S]` by whole pixels; what moves in is empty."""
    out = np.zeros_like(window)
    size = window.shape[1]
    src_y, dst_y = slice(max(0, -dy), size - max(0, dy)), slice(max(0, dy), size - max(0, -dy))
    src_x, dst_x = slice(max(0, -dx), size - max(0, dx)), slice(max(0, dx), size - max(0, -dx))
    out[:, dst_y, dst_x] = window[:, src_y, src_x]
    return out


def check_shift(shift_px: int, size: int):
    """A shift of half the image or more moves a person seen at its centre out of it (the
    window would be trained on, empty, as their activity); one of the whole image cannot be
    made at all. Known only once the dataset's image size is."""
    if 2 * shift_px >= size:
        raise DatasetError(f"--shift-px {shift_px}: the dataset's images are {size} pixels wide, and a shift of "
                           f"half that or more moves the person out of the image (at most {(size - 1) // 2})")


def augment(batch: np.ndarray, rng: np.random.Generator, shift_px: int = 0) -> np.ndarray:
    """One of the eight square symmetries per window (same for all its frames), then a shift
    of up to `shift_px` pixels each way: the localiser's position error moves the person in
    the image, and the model should not care."""
    out = np.empty_like(batch)
    for i, window in enumerate(batch):
        k = int(rng.integers(4))
        w = np.rot90(window, k, axes=(1, 2))
        if rng.integers(2):
            w = w[:, :, ::-1]
        if shift_px > 0:
            dy, dx = (int(v) for v in rng.integers(-shift_px, shift_px + 1, size=2))
            w = shift(w, dy, dx)
        out[i] = w
    return out


def class_weights_for_sampling(labels_last: np.ndarray) -> np.ndarray:
    counts = np.bincount(labels_last, minlength=len(CLASSES)).astype(np.float64)
    per_class = np.where(counts > 0, 1.0 / np.maximum(counts, 1), 0.0)
    weights = per_class[labels_last]
    return weights / weights.sum()


def loss_on_second_half(logits: torch.Tensor, labels: torch.Tensor, mask: np.ndarray | None = None) -> torch.Tensor:
    """Cross-entropy over the steps from T/2 on; with `mask` (`[B, T]`), over its true steps only."""
    half = logits.shape[1] // 2
    losses = nn.functional.cross_entropy(
        logits[:, half:].reshape(-1, len(CLASSES)), labels[:, half:].reshape(-1), reduction="none")
    if mask is None:
        return losses.mean()
    weights = torch.from_numpy(mask[:, half:].reshape(-1).astype(np.float32)).to(logits.device)
    return (losses * weights).sum() / weights.sum().clamp(min=1.0)


@torch.no_grad()
def predict(model: ActivityConvLSTM, split: Split, batch: int = 256) -> np.ndarray:
    """Logits `[N, T, 9]` over the split's windows, each from a zero state."""
    model.eval()
    out = []
    for start in range(0, len(split), batch):
        # A copy of the batch: a mapped split's slice is read-only, which torch.from_numpy warns about.
        out.append(model(to_tensor(np.array(split.images[start : start + batch]), model.device)).cpu().numpy())
    return np.concatenate(out) if out else np.zeros((0, split.images.shape[1], len(CLASSES)), np.float32)


def summarise(logits: np.ndarray, split: Split, only_visible_last: bool = False) -> dict:
    """Accuracy at the window's last step (history T) and at step T/2 (the shortest history);
    with `only_visible_last`, over the windows whose last scan saw the person."""
    if only_visible_last:
        keep = split.seen[:, -1]
        logits, labels = logits[keep], split.labels[keep]
    else:
        labels = split.labels
    steps = logits.shape[1]
    last = logits[:, -1].argmax(-1)
    half = logits[:, steps // 2].argmax(-1)
    truth_last = labels[:, -1]
    truth_half = labels[:, steps // 2]
    confusion = np.zeros((len(CLASSES), len(CLASSES)), dtype=np.int64)
    np.add.at(confusion, (truth_last, last), 1)
    recall = {
        CLASSES[k]: float(confusion[k, k] / confusion[k].sum()) if confusion[k].sum() else None
        for k in range(len(CLASSES))
    }
    return {
        "windows": int(len(logits)),
        "accuracy_at_T": float((last == truth_last).mean()),
        "accuracy_at_T_half": float((half == truth_half).mean()),
        "recall_at_T": recall,
        "confusion_at_T": confusion.tolist(),
    }


# The time counts for the learning rate only once it is this share of the budget ahead of
# the steps: the first steps' own wall time (a GPU's warm-up too) must not change the rate of
# a run whose epochs bind, or a fixed seed would not repeat it.
TIME_SLACK = 0.02


def learning_rate(args, epochs_done: int, step: int, elapsed_s: float) -> float:
    """Cosine decay over the training's progress: by steps, or by time when the budget binds.

    A fixed rate left the validation accuracy jumping by several points between epochs at the
    end; decaying it settles the weights into the best of the last basin.
    """
    by_steps = (epochs_done * args.steps_per_epoch + step) / (args.max_epochs * args.steps_per_epoch)
    by_time = (elapsed_s / (60 * args.time_budget_min) - TIME_SLACK) / (1 - TIME_SLACK)
    progress = min(1.0, max(by_steps, by_time))
    return args.lr_final + 0.5 * (args.lr - args.lr_final) * (1 + math.cos(math.pi * progress))


def train(args) -> int:
    device = choose_device(args.device)
    seed_everything(args.seed, args.threads, device)
    rng = np.random.default_rng(args.seed)
    prepare_output(args.out)
    index = load_index(args.data)
    spec = index["spec"]
    check_shift(args.shift_px, spec["size"])
    # Mapped: the two parts are copies of the windows they take (the only copies in memory);
    # a loaded whole split beside them doubled the images' memory at its peak.
    train_all = load_split(args.data, index, "train", mapped=True)
    if train_all is None:
        raise DatasetError(f"{args.data}: the train split is empty")
    train_split, val_split = split_validation(train_all, args.val_fraction, rng)
    del train_all
    print(f"train {len(train_split)} windows, validation {len(val_split)} windows "
          f"({len(np.unique(val_split.episodes))} episodes)", flush=True)

    if args.init_from is None:
        model = ActivityConvLSTM(spec["size"], hidden=args.hidden, encoder_channels=args.encoder_channels)
    else:
        model = model_from_onnx(args.init_from, spec)
        args.hidden, args.encoder_channels = model.hidden, model.encoder_channels
        print(f"starting from the weights of {args.init_from}", flush=True)
    params = sum(p.numel() for p in model.parameters())
    print(f"model: size {spec['size']}, hidden {args.hidden}, encoder {args.encoder_channels}, "
          f"{params} parameters, training on {device}", flush=True)
    model.to(device)
    optimiser = torch.optim.Adam(model.parameters(), lr=args.lr)
    sampling = class_weights_for_sampling(train_split.labels[:, -1])

    best_state, best_val, best_epoch, history = None, -1.0, 0, []
    started = time.monotonic()
    for epoch in range(1, args.max_epochs + 1):
        model.train()
        total = 0.0
        for step in range(args.steps_per_epoch):
            rows = np.sort(rng.choice(len(train_split), size=args.batch, p=sampling))
            images = train_split.images[rows]
            mask = train_split.seen[rows] if args.mask_hidden_steps else None
            if not args.no_augment:
                images = augment(images, rng, args.shift_px)
            with torch.autocast(device.type, dtype=torch.bfloat16, enabled=args.bf16):
                logits = model(to_tensor(np.ascontiguousarray(images), device))
            labels = torch.from_numpy(train_split.labels[rows]).to(device)
            loss = loss_on_second_half(logits.float(), labels, mask)
            lr = learning_rate(args, epoch - 1, step, time.monotonic() - started)
            for group in optimiser.param_groups:
                group["lr"] = lr
            optimiser.zero_grad()
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), 5.0)
            optimiser.step()
            total += loss.item()
        val = summarise(predict(model, val_split), val_split, args.mask_hidden_steps)
        # Balanced validation score: mean recall at T, so rare classes (falls) count as much.
        recalls = [r for r in val["recall_at_T"].values() if r is not None]
        score = float(np.mean(recalls)) if recalls else 0.0
        elapsed = time.monotonic() - started
        history.append({"epoch": epoch, "loss": total / args.steps_per_epoch, "val_accuracy": val["accuracy_at_T"],
                        "val_balanced_recall": score, "elapsed_s": round(elapsed, 1)})
        print(f"epoch {epoch:3d} loss {total / args.steps_per_epoch:.4f} val acc {val['accuracy_at_T']:.4f} "
              f"balanced recall {score:.4f} ({elapsed / 60:.1f} min)", flush=True)
        if score > best_val:
            best_val, best_epoch = score, epoch
            best_state = {k: v.clone() for k, v in model.state_dict().items()}
        elif epoch - best_epoch >= args.patience:
            print(f"early stop: no validation gain for {args.patience} epochs", flush=True)
            break
        if elapsed > args.time_budget_min * 60:
            print(f"time budget of {args.time_budget_min} min reached", flush=True)
            break
    training_s = time.monotonic() - started
    model.load_state_dict(best_state)
    model.eval()
    print(f"best epoch {best_epoch}: validation balanced recall {best_val:.4f}", flush=True)

    results = {"validation": summarise(predict(model, val_split), val_split, args.mask_hidden_steps)}
    for name in () if args.skip_test_eval else ("test", "test_unseen"):
        split = load_split(args.data, index, name, mapped=True)
        if split is not None:
            results[name] = summarise(predict(model, split), split)
            print(f"{name}: accuracy at T {results[name]['accuracy_at_T']:.4f}, "
                  f"at T/2 {results[name]['accuracy_at_T_half']:.4f} ({len(split)} windows)", flush=True)

    # Mapped: 16 windows are read, not the whole split.
    parity_split = load_split(args.data, index, "test", mapped=True) or val_split
    parity = export_step_model(model.cpu(), spec, args.out, parity_split.images[:16])
    parity_max = max(f["max_abs_diff"] for f in parity["step"].values())
    report = {
        "date_utc": datetime.now(timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
        "data": str(args.data),
        "dataset_generator": index.get("generator"),
        "spec": spec,
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "parameters": params,
        "best_epoch": best_epoch,
        "training_seconds": round(training_s, 1),
        "torch_threads": torch.get_num_threads(),
        "device": torch.cuda.get_device_name(device) if device.type == "cuda" else "cpu",
        "history": history,
        "results": results,
        "parity_max_abs_diff": parity_max,
        "parity": parity,
    }
    report_path = args.out.with_suffix(".training.json")
    report_path.write_text(report_json(report))

    def per_output(kind):
        return ", ".join(f"{name} {f['max_abs_diff']:.2e} (values up to {f['max_abs_value']:.1f})"
                         for name, f in parity[kind].items())

    print(f"wrote {args.out} and {report_path} (parity, max abs diff per step: {per_output('step')}; "
          f"over whole windows: {per_output('window')})", flush=True)
    return 0


def main(argv=None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    try:
        return train(args)
    except (DatasetError, DeviceError, ExportError, OutputError) as err:
        print(f"train: error: {err}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
