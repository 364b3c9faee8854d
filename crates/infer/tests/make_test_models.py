"""Builds the small ONNX step models the infer crate is tested with, and the expected outputs.

A real (tiny) ConvLSTM cell with the names and shapes of docs/model_contract.md, random
weights from a fixed seed, so the tests exercise ONNX Runtime for real without depending on a
trained model. The expected logits come from an independent NumPy implementation of the same
cell, so the Rust side is checked against arithmetic, not against itself.

Run from the repository root:  .venv/bin/python crates/infer/tests/make_test_models.py
It rewrites crates/infer/tests/fixtures/ (deterministic: same bytes every run).

For benchmarks, `--size S --hidden H --out FILE` writes one untrained model of that size
instead (state side S/2), e.g. to time a 64x64 image with 16 hidden channels:
  .venv/bin/python crates/infer/tests/make_test_models.py --size 64 --hidden 16 --out /tmp/m.onnx
  cargo bench -p lidar-har-infer --bench classify -- /tmp/m.onnx
"""

import hashlib
import json
import pathlib

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

SIZE, HIDDEN, HS, CLASSES = 16, 4, 8, 9
OUT = pathlib.Path(__file__).parent / "fixtures"

METADATA = {
    "lidar_har.representation": "boolean_grid",
    "lidar_har.framing": "person_centred",
    "lidar_har.size": str(SIZE),
    "lidar_har.resolution_m": "0.1",
    "lidar_har.window": "8",
    "lidar_har.scan_rate_hz": "20",
}


def weights(logit_scale=1.0, classes=CLASSES, hidden=HIDDEN):
    """Random weights of the cell, fixed seed."""
    rng = np.random.default_rng(5)
    return {
        "w_conv": rng.normal(0.0, 0.4, (4 * hidden, 1 + hidden, 3, 3)).astype(np.float32),
        "b_conv": rng.normal(0.0, 0.1, (4 * hidden,)).astype(np.float32),
        "w_out": (rng.normal(0.0, 1.0, (hidden, classes)) * logit_scale).astype(np.float32),
        "b_out": rng.normal(0.0, 0.1, (classes,)).astype(np.float32),
    }


def build(w, frame_name="frame", classes=CLASSES, metadata=METADATA, hidden=HIDDEN, frame_type=TensorProto.FLOAT):
    f = TensorProto.FLOAT
    inputs = [
        helper.make_tensor_value_info(frame_name, frame_type, [1, 1, SIZE, SIZE]),
        helper.make_tensor_value_info("h", f, [1, hidden, HS, HS]),
        helper.make_tensor_value_info("c", f, [1, hidden, HS, HS]),
    ]
    outputs = [
        helper.make_tensor_value_info("logits", f, [1, classes]),
        helper.make_tensor_value_info("h_next", f, [1, hidden, HS, HS]),
        helper.make_tensor_value_info("c_next", f, [1, hidden, HS, HS]),
    ]
    init = [numpy_helper.from_array(v, k) for k, v in w.items()]
    init.append(numpy_helper.from_array(np.array([hidden] * 4, dtype=np.int64), "split"))
    n = helper.make_node
    # A frame of another element type is cast to float32 first: the graph is valid, only its
    # input breaks the contract.
    cast = [] if frame_type == f else [n("Cast", [frame_name], ["frame_f32"], to=f)]
    pool_input = frame_name if frame_type == f else "frame_f32"
    nodes = cast + [
        n("MaxPool", [pool_input], ["pooled"], kernel_shape=[2, 2], strides=[2, 2]),
        n("Concat", ["pooled", "h"], ["x"], axis=1),
        n("Conv", ["x", "w_conv", "b_conv"], ["gates"], pads=[1, 1, 1, 1]),
        n("Split", ["gates", "split"], ["gi", "gf", "go", "gg"], axis=1),
        n("Sigmoid", ["gi"], ["i"]),
        n("Sigmoid", ["gf"], ["f"]),
        n("Sigmoid", ["go"], ["o"]),
        n("Tanh", ["gg"], ["g"]),
        n("Mul", ["f", "c"], ["fc"]),
        n("Mul", ["i", "g"], ["ig"]),
        n("Add", ["fc", "ig"], ["c_next"]),
        n("Tanh", ["c_next"], ["tc"]),
        n("Mul", ["o", "tc"], ["h_next"]),
        n("GlobalAveragePool", ["h_next"], ["hp"]),
        n("Flatten", ["hp"], ["hf"]),
        n("Gemm", ["hf", "w_out", "b_out"], ["logits"]),
    ]
    graph = helper.make_graph(nodes, "convlstm_step_test", inputs, outputs, init)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="lidar_har tests")
    model.ir_version = 8
    for k, v in metadata.items():
        model.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(model, full_check=True)
    return model


# Every class: the untrained test model's readings are arbitrary, and a run with the head
# should place a pelvis on every seen scan.
ACTIVITIES = ["crawling", "falling_down", "getting_up", "lying_down", "running", "sitting_on_floor",
              "standing", "walking", "walking_unsteadily"]
# Where the person lies in the image for the expected pose head output (metres from its centre).
POSE_HEAD_LOCATED = [0.3, -0.2]
POSE_HEAD_METADATA = {
    "lidar_har.pose_head.min_history": "3",
    "lidar_har.pose_head.activities": ",".join(ACTIVITIES),
    "lidar_har.pose_head.max_sigma_m": "inf",
}


def pose_head_weights():
    rng = np.random.default_rng(7)
    return {
        "w_state": rng.normal(0.0, 0.5, (HIDDEN, 2)).astype(np.float32),
        "w_located": rng.normal(0.0, 0.5, (2, 2)).astype(np.float32),
        "b_offset": rng.normal(0.0, 0.1, (2,)).astype(np.float32),
        "w_sigma": rng.normal(0.0, 0.5, (HIDDEN, 1)).astype(np.float32),
        "b_sigma": np.full((1,), -2.5, np.float32),
    }


def build_pose_head(w, activity_sha256, hidden=HIDDEN, sigma=True):
    """A tiny pose head with the contract's names: offset = mean(h) W_state + located
    W_located + b, sigma = exp(mean(h) W_sigma + b_sigma) (without `sigma`: a head of the
    contract before session 24)."""
    f = TensorProto.FLOAT
    inputs = [
        helper.make_tensor_value_info("h", f, [1, hidden, HS, HS]),
        helper.make_tensor_value_info("located", f, [1, 2]),
    ]
    outputs = [helper.make_tensor_value_info("offset", f, [1, 2])]
    if sigma:
        outputs.append(helper.make_tensor_value_info("sigma", f, [1, 1]))
    else:
        w = {k: v for k, v in w.items() if "sigma" not in k}
    init = [numpy_helper.from_array(v, k) for k, v in w.items()]
    n = helper.make_node
    nodes = [
        n("GlobalAveragePool", ["h"], ["hp"]),
        n("Flatten", ["hp"], ["hf"]),
        n("MatMul", ["hf", "w_state"], ["from_state"]),
        n("MatMul", ["located", "w_located"], ["from_located"]),
        n("Add", ["from_state", "from_located"], ["sum"]),
        n("Add", ["sum", "b_offset"], ["offset"]),
    ]
    if sigma:
        nodes += [
            n("MatMul", ["hf", "w_sigma"], ["sigma_state"]),
            n("Add", ["sigma_state", "b_sigma"], ["log_sigma"]),
            n("Exp", ["log_sigma"], ["sigma"]),
        ]
    graph = helper.make_graph(nodes, "pose_head_test", inputs, outputs, init)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)], producer_name="lidar_har tests")
    model.ir_version = 8
    for k, v in {**POSE_HEAD_METADATA, "lidar_har.pose_head.activity_sha256": activity_sha256}.items():
        model.metadata_props.add(key=k, value=v)
    onnx.checker.check_model(model, full_check=True)
    return model


def reference_pose_head(w, h, located):
    """The offset and the deviation."""
    pooled = h.mean(axis=(1, 2))
    return (pooled @ w["w_state"] + np.asarray(located) @ w["w_located"] + w["b_offset"],
            float(np.exp(pooled @ w["w_sigma"] + w["b_sigma"])[0]))


def sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def reference_step(w, frame, h, c):
    """The same cell in NumPy (float64), independent of ONNX."""
    pooled = frame.reshape(SIZE // 2, 2, SIZE // 2, 2).max(axis=(1, 3))
    x = np.concatenate([pooled[None], h], axis=0).astype(np.float64)
    xp = np.pad(x, ((0, 0), (1, 1), (1, 1)))
    gates = np.zeros((4 * HIDDEN, HS, HS))
    for r in range(HS):
        for q in range(HS):
            patch = xp[:, r : r + 3, q : q + 3]
            gates[:, r, q] = np.tensordot(w["w_conv"], patch, axes=3) + w["b_conv"]
    gi, gf, go, gg = np.split(gates, 4, axis=0)
    c_next = sigmoid(gf) * c + sigmoid(gi) * np.tanh(gg)
    h_next = sigmoid(go) * np.tanh(c_next)
    logits = h_next.mean(axis=(1, 2)) @ w["w_out"] + w["b_out"]
    return logits, h_next, c_next


def frames(count):
    """A person-like blob moving across the image, with an empty (hidden) frame in between."""
    out = []
    for k in range(count):
        img = np.zeros((SIZE, SIZE), dtype=np.float32)
        if k != 3:
            img[6 + k % 3 : 9 + k % 3, 2 + 2 * k : 4 + 2 * k] = 1.0
        out.append(img)
    return out


def main():
    OUT.mkdir(exist_ok=True)
    w = weights()
    onnx.save(build(w), OUT / "step_model.onnx")
    onnx.save(build(weights(logit_scale=1e4)), OUT / "saturating_model.onnx")
    onnx.save(build(w, frame_name="image"), OUT / "wrong_input_name.onnx")
    onnx.save(build(w, frame_type=TensorProto.DOUBLE), OUT / "float64_frame.onnx")
    onnx.save(build(weights(classes=8), classes=8), OUT / "wrong_class_count.onnx")
    onnx.save(build(w, metadata={k: v for k, v in METADATA.items() if k != "lidar_har.window"}), OUT / "missing_window.onnx")
    onnx.save(build(w, metadata={**METADATA, "lidar_har.size": "32"}), OUT / "size_mismatch.onnx")
    # A valid model whose state does not fit step_model.onnx (3 hidden channels, not 4).
    onnx.save(build(weights(hidden=3), hidden=3), OUT / "three_channel_model.onnx")
    # A broken model: a NaN in the gates' bias makes every output NaN (logits and state).
    onnx.save(build({**w, "b_conv": np.full_like(w["b_conv"], np.nan)}), OUT / "nan_model.onnx")

    step_sha256 = hashlib.sha256((OUT / "step_model.onnx").read_bytes()).hexdigest()
    head = pose_head_weights()
    onnx.save(build_pose_head(head, step_sha256), OUT / "pose_head.onnx")
    onnx.save(build_pose_head(head, hashlib.sha256(b"another model").hexdigest()), OUT / "pose_head_other_model.onnx")
    onnx.save(build_pose_head({**head, "w_state": head["w_state"][:3], "w_sigma": head["w_sigma"][:3]}, step_sha256, hidden=3),
              OUT / "pose_head_wrong_state.onnx")
    onnx.save(build_pose_head(head, step_sha256, sigma=False), OUT / "pose_head_without_sigma.onnx")

    h = np.zeros((HIDDEN, HS, HS))
    c = np.zeros((HIDDEN, HS, HS))
    seq = frames(6)
    logits = []
    for frame in seq:
        out, h, c = reference_step(w, frame.astype(np.float64), h, c)
        logits.append([float(v) for v in out])
    offset, sigma = reference_pose_head(head, h, POSE_HEAD_LOCATED)
    expected = {
        "frames": [[float(v) for v in f.ravel()] for f in seq],
        "logits": logits,
        "h_final_sum": float(h.sum()),
        "pose_head": {"located": POSE_HEAD_LOCATED,
                      "offset": [float(v) for v in offset], "sigma": sigma},
    }
    (OUT / "step_model_expected.json").write_text(json.dumps(expected) + "\n")


def bench_model(argv):
    global SIZE, HIDDEN, HS
    args = dict(zip(argv[::2], argv[1::2]))
    SIZE, HIDDEN = int(args["--size"]), int(args["--hidden"])
    HS = SIZE // 2
    onnx.save(build(weights(hidden=HIDDEN), metadata={**METADATA, "lidar_har.size": str(SIZE)}, hidden=HIDDEN),
              args["--out"])


if __name__ == "__main__":
    import sys

    if len(sys.argv) > 1:
        bench_model(sys.argv[1:])
    else:
        main()
