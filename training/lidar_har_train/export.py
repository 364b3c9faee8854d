"""ONNX export of the per-scan step model, with metadata and a parity check against PyTorch.

The exported graph is `(frame, h, c) -> (logits, h_next, c_next)` (docs/model_contract.md).
Parity: whole windows are stepped through ONNX Runtime and through PyTorch from zero states;
the largest difference of logits and states must be at most 1e-5 absolute for values up to 1
in magnitude, and 1e-5 of the largest magnitude above that (float32 keeps about seven digits:
a cell state of 20 cannot agree to 1e-5 absolute once the two runtimes sum in different
orders); else the export fails and the file is removed. The report keeps the raw absolute
figure too.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnx
import onnxruntime as ort
import torch

from .model import ActivityConvLSTM, StepModel

PARITY_TOLERANCE = 1e-5
SCAN_RATE_HZ_DEFAULT = 20.0


class ExportError(Exception):
    pass


def export_step_model(model: ActivityConvLSTM, spec: dict, out: Path,
                      windows_u8: np.ndarray) -> tuple[float, float]:
    """Writes `out`; returns the parity figures over `windows_u8`: the max absolute difference,
    and the max difference over max(1, the tensor's largest magnitude) that the check uses."""
    model.eval()
    out.parent.mkdir(parents=True, exist_ok=True)
    size, hidden, hs = model.size, model.hidden, model.state_size
    frame = torch.rand(1, 1, size, size)
    # Separate, different example tensors for h and c: one shared zeros tensor makes the
    # exporter merge the two inputs (FINDINGS.md).
    h = torch.rand(1, hidden, hs, hs) * 0.1
    c = torch.rand(1, hidden, hs, hs) * 0.2
    torch.onnx.export(
        StepModel(model),
        (frame, h, c),
        str(out),
        input_names=["frame", "h", "c"],
        output_names=["logits", "h_next", "c_next"],
        opset_version=18,
        dynamo=False,
    )
    proto = onnx.load(str(out))
    meta = {
        "lidar_har.representation": spec["representation"],
        "lidar_har.framing": spec["framing"],
        "lidar_har.size": str(spec["size"]),
        "lidar_har.resolution_m": str(spec["resolution_m"]),
        "lidar_har.window": str(spec["window"]),
        "lidar_har.scan_rate_hz": str(spec.get("scan_rate_hz", SCAN_RATE_HZ_DEFAULT)),
        "lidar_har.hidden": str(hidden),
    }
    del proto.metadata_props[:]
    for key, value in meta.items():
        entry = proto.metadata_props.add()
        entry.key, entry.value = key, value
    proto.doc_string = "lidar_har activity ConvLSTM step model (docs/model_contract.md)"
    onnx.checker.check_model(proto)
    check_io(proto, size, hidden, hs)
    onnx.save(proto, str(out))
    try:
        diff, scaled = parity(model, out, windows_u8)
    except Exception:
        out.unlink(missing_ok=True)
        raise
    if not scaled <= PARITY_TOLERANCE:
        out.unlink(missing_ok=True)
        raise ExportError(f"parity check failed: max difference {scaled:.3e} of the tensors' scale "
                          f"(absolute {diff:.3e}) > {PARITY_TOLERANCE:.0e}")
    return diff, scaled


def check_io(proto, size: int, hidden: int, hs: int):
    def shapes(values):
        return {v.name: [d.dim_value for d in v.type.tensor_type.shape.dim] for v in values}

    want_in = {"frame": [1, 1, size, size], "h": [1, hidden, hs, hs], "c": [1, hidden, hs, hs]}
    want_out = {"logits": [1, 9], "h_next": [1, hidden, hs, hs], "c_next": [1, hidden, hs, hs]}
    got_in, got_out = shapes(proto.graph.input), shapes(proto.graph.output)
    if got_in != want_in or got_out != want_out:
        raise ExportError(f"exported I/O {got_in} -> {got_out} differs from the contract {want_in} -> {want_out}")


@torch.no_grad()
def parity(model: ActivityConvLSTM, path: Path, windows_u8: np.ndarray) -> tuple[float, float]:
    options = ort.SessionOptions()
    options.intra_op_num_threads = 1
    session = ort.InferenceSession(str(path), options, providers=["CPUExecutionProvider"])
    worst, worst_scaled = 0.0, 0.0
    for window in windows_u8:
        frames = window.astype(np.float32) / 255.0
        h_t, c_t = model.zero_state(1)
        h_o, c_o = h_t.numpy(), c_t.numpy()
        for frame in frames:
            x = frame[None, None]
            logits_t, h_t, c_t = model.step(torch.from_numpy(x), h_t, c_t)
            logits_o, h_o, c_o = session.run(["logits", "h_next", "c_next"], {"frame": x, "h": h_o, "c": c_o})
            for a, b in ((logits_t, logits_o), (h_t, h_o), (c_t, c_o)):
                diff = float(np.abs(a.numpy() - b).max())
                worst = max(worst, diff)
                worst_scaled = max(worst_scaled, diff / max(1.0, float(np.abs(a.numpy()).max())))
    return worst, worst_scaled
