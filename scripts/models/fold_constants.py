"""Fold DENSIFY and DEQUANTIZE ops on constant weights of a .tflite model into dense fp32 buffers.

MediaPipe's .tflite models store weights as fp16 behind DEQUANTIZE ops, and pose_detection also
stores some as sparse tensors behind DENSIFY ops. tf2onnx turns the model into a TensorFlow graph
first, and TensorFlow cannot import sparse TFLite tensors. This helper evaluates every such op
whose inputs are constant (with the TFLite interpreter, so the densification is TFLite's own),
writes the result into the op's output tensor as a plain constant, deletes the op and prunes the
tensors and buffers nothing uses any more. The rest of the graph is untouched.

Usage (in the converter venv, which has tensorflow):
    python fold_constants.py IN.tflite OUT.tflite
"""

import sys

import numpy as np
import tensorflow as tf
from tensorflow.lite.python import schema_py_generated as schema
from tensorflow.lite.tools import flatbuffer_utils

FOLDABLE = {"DENSIFY", "DEQUANTIZE"}

NP_TYPE = {
    schema.TensorType.FLOAT32: np.float32,
    schema.TensorType.FLOAT16: np.float16,
    schema.TensorType.INT8: np.int8,
    schema.TensorType.UINT8: np.uint8,
    schema.TensorType.INT32: np.int32,
}


def op_name(model, op):
    return flatbuffer_utils.opcode_to_name(model, op.opcodeIndex)


def has_data(model, tensor):
    buf = model.buffers[tensor.buffer]
    return buf.data is not None and len(buf.data) > 0


def fold(in_path, out_path):
    model = flatbuffer_utils.read_model(in_path)
    if len(model.subgraphs) != 1:
        raise SystemExit(f"{in_path}: expected one subgraph, found {len(model.subgraphs)}")
    sg = model.subgraphs[0]

    # Ops to fold: DENSIFY/DEQUANTIZE whose inputs are constant, possibly through another folded op.
    const = {i for i, t in enumerate(sg.tensors) if has_data(model, t)}
    fold_ops = []
    changed = True
    while changed:
        changed = False
        for k, op in enumerate(sg.operators):
            if k in fold_ops or op_name(model, op) not in FOLDABLE:
                continue
            if all(i in const for i in op.inputs if i >= 0):
                fold_ops.append(k)
                const.update(op.outputs)
                changed = True
    if not fold_ops:
        flatbuffer_utils.write_model(model, out_path)
        print(f"{in_path}: nothing to fold")
        return

    # Values of the folded ops' outputs, as TFLite computes them.
    # No default delegate (XNNPACK would take the fp16 weights itself and not materialise them).
    interp = tf.lite.Interpreter(
        model_path=in_path,
        experimental_preserve_all_tensors=True,
        experimental_op_resolver_type=tf.lite.experimental.OpResolverType.BUILTIN_WITHOUT_DEFAULT_DELEGATES,
    )
    interp.allocate_tensors()
    for d in interp.get_input_details():
        interp.set_tensor(d["index"], np.zeros(d["shape"], d["dtype"]))
    interp.invoke()
    values = {}
    for k in fold_ops:
        for o in sg.operators[k].outputs:
            v = interp.get_tensor(o)
            t = sg.tensors[o]
            want = NP_TYPE[t.type]
            if v.dtype != want:
                raise SystemExit(f"{in_path}: tensor {o} has dtype {v.dtype}, schema says {want}")
            if list(v.shape) != list(t.shape):
                raise SystemExit(f"{in_path}: tensor {o} has shape {v.shape}, schema says {t.shape}")
            op = sg.operators[k]
            src = sg.tensors[op.inputs[0]]
            if op_name(model, op) == "DEQUANTIZE" and has_data(model, src) and src.type == schema.TensorType.FLOAT16:
                # Cross-check TFLite against a plain fp16 -> fp32 cast of the stored weights.
                raw = np.frombuffer(bytes(model.buffers[src.buffer].data), dtype=np.float16).reshape(v.shape)
                if not np.array_equal(raw.astype(np.float32), v):
                    raise SystemExit(f"{in_path}: DEQUANTIZE of tensor {op.inputs[0]} disagrees with fp16 cast")
            values[o] = v

    for o, v in values.items():
        buf = schema.BufferT()
        buf.data = np.frombuffer(np.ascontiguousarray(v).tobytes(), dtype=np.uint8)
        model.buffers.append(buf)
        sg.tensors[o].buffer = len(model.buffers) - 1
        sg.tensors[o].sparsity = None
        sg.tensors[o].quantization = None
    counts = {}
    for k in fold_ops:
        name = op_name(model, sg.operators[k])
        counts[name] = counts.get(name, 0) + 1
    sg.operators = [op for k, op in enumerate(sg.operators) if k not in set(fold_ops)]

    # Prune tensors no op or graph input/output refers to, then buffers no tensor refers to.
    used = set(sg.inputs) | set(sg.outputs)
    for op in sg.operators:
        used.update(i for i in op.inputs if i >= 0)
        used.update(op.outputs)
        if op.intermediates is not None:
            used.update(op.intermediates)
    keep = sorted(used)
    remap = {old: new for new, old in enumerate(keep)}

    def re(ix):
        return [remap[i] if i >= 0 else i for i in ix]

    sg.tensors = [sg.tensors[i] for i in keep]
    sg.inputs = re(sg.inputs)
    sg.outputs = re(sg.outputs)
    for op in sg.operators:
        op.inputs = re(op.inputs)
        op.outputs = re(op.outputs)
        if op.intermediates is not None:
            op.intermediates = re(op.intermediates)
    # Buffer 0 is the empty sentinel by convention; keep it first.
    used_bufs = sorted({0} | {t.buffer for t in sg.tensors})
    bremap = {old: new for new, old in enumerate(used_bufs)}
    model.buffers = [model.buffers[b] for b in used_bufs]
    for t in sg.tensors:
        t.buffer = bremap[t.buffer]
    # Metadata entries point at buffers too (e.g. min_runtime_version); keep them valid or drop them.
    if model.metadata is not None:
        model.metadata = [m for m in model.metadata if m.buffer in bremap]
        for m in model.metadata:
            m.buffer = bremap[m.buffer]
    model.metadataBuffer = None

    flatbuffer_utils.write_model(model, out_path)
    print(f"{in_path}: folded {counts}, {len(sg.operators)} ops left")


if __name__ == "__main__":
    if len(sys.argv) != 3:
        raise SystemExit(__doc__)
    fold(sys.argv[1], sys.argv[2])
