"""Where a training step's time goes: the model's forward and backward pass on one batch as
`train.py` runs it, the same with the encoder run once over all frames of the window (the
same arithmetic in fewer, larger convolutions), and one validation pass. Random images of
the committed model's size; prints seconds, asserts nothing.

    PYTHONPATH=training training/.venv/bin/python training/experiments/step_time.py \\
        [--hidden 32] [--encoder-channels 16] [--batch 64] [--window 20] [--bf16]
"""
import argparse
import time

import torch
from torch import nn

from lidar_har_train.model import ActivityConvLSTM

SIZE = 32


def encoder_batched(model: ActivityConvLSTM, frames: torch.Tensor) -> torch.Tensor:
    """`model(frames)` with the encoder applied to all frames in one call."""
    batch, steps = frames.shape[:2]
    encoded = model.encoder(frames.reshape(batch * steps, 1, SIZE, SIZE))
    encoded = encoded.reshape(batch, steps, *encoded.shape[1:])
    h, c = model.zero_state(batch)
    hidden = []
    for t in range(steps):
        h, c = model.cell(encoded[:, t], h, c)
        hidden.append(h)
    h_all = torch.stack(hidden, 1).flatten(0, 1)
    pooled = torch.cat([h_all.mean(dim=(2, 3)), h_all.amax(dim=(2, 3))], 1)
    return model.head(pooled).reshape(batch, steps, -1)


def seconds_per_step(forward, model, frames, labels, bf16: bool, repeats: int = 10) -> float:
    optimiser = torch.optim.Adam(model.parameters(), lr=1e-3)
    half = frames.shape[1] // 2

    def step():
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=bf16):
            logits = forward(frames)
        loss = nn.functional.cross_entropy(logits.float()[:, half:].reshape(-1, 9), labels[:, half:].reshape(-1))
        optimiser.zero_grad()
        loss.backward()
        optimiser.step()

    for _ in range(3):
        step()
    started = time.perf_counter()
    for _ in range(repeats):
        step()
    return (time.perf_counter() - started) / repeats


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--hidden", type=int, default=32)
    p.add_argument("--encoder-channels", type=int, default=16)
    p.add_argument("--batch", type=int, default=64)
    p.add_argument("--window", type=int, default=20)
    p.add_argument("--validation-windows", type=int, default=5688)
    p.add_argument("--bf16", action="store_true")
    args = p.parse_args()
    torch.set_num_threads(2)
    torch.use_deterministic_algorithms(True)
    torch.manual_seed(7)
    model = ActivityConvLSTM(SIZE, hidden=args.hidden, encoder_channels=args.encoder_channels)
    # About 2 % of the pixels lit, as in the Boolean-grid images.
    frames = (torch.rand(args.batch, args.window, SIZE, SIZE) < 0.02).float()
    labels = torch.randint(0, 9, (args.batch, args.window))
    with torch.no_grad():
        difference = (encoder_batched(model, frames) - model(frames)).abs().max().item()
    print(f"encoder batched over the window: same logits within {difference:.1e}")
    for name, forward in (("as train.py", model), ("encoder batched", lambda f: encoder_batched(model, f))):
        print(f"training step, {name}: {seconds_per_step(forward, model, frames, labels, args.bf16):.3f} s")
    validation = (torch.rand(args.validation_windows, args.window, SIZE, SIZE) < 0.02).float()
    started = time.perf_counter()
    with torch.no_grad():
        for start in range(0, len(validation), 256):
            model(validation[start : start + 256])
    print(f"validation pass over {args.validation_windows} windows (float32): {time.perf_counter() - started:.1f} s")


if __name__ == "__main__":
    main()
