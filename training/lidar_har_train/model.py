"""The activity ConvLSTM: a small frame encoder, a ConvLSTM cell written out, a classifier head.

The model is built around one step (`step`): a frame and the previous state in, logits and
the next state out. Training unrolls it over a window; export writes exactly that step to
ONNX (docs/model_contract.md), so streaming costs one step per scan.
"""

from __future__ import annotations

import torch
from torch import nn

NUM_CLASSES = 9


class ConvLSTMCell(nn.Module):
    """One convolution over [input, hidden] gives the four gates i, f, o, g."""

    def __init__(self, in_channels: int, hidden: int, kernel: int = 3):
        super().__init__()
        self.hidden = hidden
        self.gates = nn.Conv2d(in_channels + hidden, 4 * hidden, kernel, padding=kernel // 2)

    def forward(self, x, h, c):
        i, f, o, g = torch.split(self.gates(torch.cat([x, h], dim=1)), self.hidden, dim=1)
        i = torch.sigmoid(i)
        f = torch.sigmoid(f)
        o = torch.sigmoid(o)
        g = torch.tanh(g)
        c_next = f * c + i * g
        h_next = o * torch.tanh(c_next)
        return h_next, c_next


class ActivityConvLSTM(nn.Module):
    """Frame `[B, 1, S, S]` -> encoder (two stride-2 convolutions, S/4) -> ConvLSTM -> head.

    The head pools the hidden state globally (mean and max: the person's points are sparse,
    the max keeps a single strong cell) and maps it linearly to the nine logits.
    """

    def __init__(self, size: int, hidden: int = 16, encoder_channels: int = 8):
        super().__init__()
        if size % 4 != 0:
            raise ValueError(f"image size {size} must be a multiple of 4")
        self.size = size
        self.hidden = hidden
        self.encoder_channels = encoder_channels
        self.state_size = size // 4
        self.encoder = nn.Sequential(
            nn.Conv2d(1, encoder_channels, 3, stride=2, padding=1),
            nn.ReLU(),
            nn.Conv2d(encoder_channels, encoder_channels, 3, stride=2, padding=1),
            nn.ReLU(),
        )
        self.cell = ConvLSTMCell(encoder_channels, hidden)
        self.head = nn.Linear(2 * hidden, NUM_CLASSES)

    @property
    def device(self) -> torch.device:
        return self.head.weight.device

    def zero_state(self, batch: int):
        shape = (batch, self.hidden, self.state_size, self.state_size)
        return torch.zeros(shape, device=self.device), torch.zeros(shape, device=self.device)

    def step(self, frame, h, c):
        h_next, c_next = self.cell(self.encoder(frame), h, c)
        pooled = torch.cat([h_next.mean(dim=(2, 3)), h_next.amax(dim=(2, 3))], dim=1)
        return self.head(pooled), h_next, c_next

    def forward(self, frames):
        """Unrolls a window `[B, T, S, S]` from a zero state; returns logits `[B, T, 9]`."""
        batch, steps = frames.shape[0], frames.shape[1]
        h, c = self.zero_state(batch)
        outputs = []
        for t in range(steps):
            logits, h, c = self.step(frames[:, t : t + 1], h, c)
            outputs.append(logits)
        return torch.stack(outputs, dim=1)


class StepModel(nn.Module):
    """What is exported: `(frame, h, c) -> (logits, h_next, c_next)`."""

    def __init__(self, model: ActivityConvLSTM):
        super().__init__()
        self.model = model

    def forward(self, frame, h, c):
        return self.model.step(frame, h, c)
