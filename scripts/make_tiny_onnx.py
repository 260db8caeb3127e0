#!/usr/bin/env python3
"""Tiny stand-ins for the SAM ONNX exports, with the real input/output names
and shapes, for testing the perception crate's model runners without weights.

  encoder: image[1,3,1024,1024] -> image_embeddings[1,256,64,64]
           (16x16 average pooling, then a fixed 1x1 convolution to 256 channels)
  decoder: image_embeddings[1,256,64,64], point_coords[1,N,2], point_labels[1,N],
           mask_input[1,1,256,256], has_mask_input[1], orig_im_size[2]
           -> masks[1,3,H,W], iou_predictions[1,3], low_res_masks[1,3,256,256]
           Mask k is "embedding within tau_k of the embedding under the first
           point", so a click selects the uniformly coloured region under it.

Requires `pip install onnx==1.23.2` (opset 17). Usage:
  python3 scripts/make_tiny_onnx.py common/perception/tests/fixtures
"""
import sys
from pathlib import Path

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper

OPSET = [helper.make_opsetid("", 17)]
GRID = 64  # embedding cells per side
CELL = 1024 // GRID  # input pixels per embedding cell
CHANNELS = 256
TAUS = [2.0, 8.0, 32.0]  # squared embedding distance of the three masks
IOUS = [0.97, 0.93, 0.80]  # fixed predicted IoU of the three masks


def const(name, array):
    return helper.make_node("Constant", [], [name], value=numpy_helper.from_array(np.asarray(array), name))


def encoder():
    rng = np.random.default_rng(0)
    weight = (rng.standard_normal((CHANNELS, 3, 1, 1)) * 0.5).astype(np.float32)
    bias = np.zeros(CHANNELS, dtype=np.float32)
    nodes = [
        helper.make_node("AveragePool", ["image"], ["pooled"], kernel_shape=[CELL, CELL], strides=[CELL, CELL]),
        helper.make_node("Conv", ["pooled", "weight", "bias"], ["image_embeddings"]),
    ]
    graph = helper.make_graph(
        nodes,
        "tiny_sam_encoder",
        [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, 1024, 1024])],
        [helper.make_tensor_value_info("image_embeddings", TensorProto.FLOAT, [1, CHANNELS, GRID, GRID])],
        [numpy_helper.from_array(weight, "weight"), numpy_helper.from_array(bias, "bias")],
    )
    return helper.make_model(graph, opset_imports=OPSET, producer_name="opengs make_tiny_onnx")


def decoder():
    n = len(TAUS)
    nodes = [
        # Embedding cell under the first point (coordinates in the 1024 frame).
        const("cell_size", np.array(float(CELL), dtype=np.float32)),
        const("grid_max", np.array(float(GRID - 1), dtype=np.float32)),
        const("zero", np.array(0.0, dtype=np.float32)),
        const("first_start", np.array([0, 0, 0], dtype=np.int64)),
        const("first_end", np.array([1, 1, 1], dtype=np.int64)),
        const("second_start", np.array([0, 0, 1], dtype=np.int64)),
        const("second_end", np.array([1, 1, 2], dtype=np.int64)),
        helper.make_node("Div", ["point_coords", "cell_size"], ["cells_f"]),
        helper.make_node("Floor", ["cells_f"], ["cells_floor"]),
        helper.make_node("Clip", ["cells_floor", "zero", "grid_max"], ["cells"]),
        helper.make_node("Slice", ["cells", "first_start", "first_end"], ["cell_x"]),
        helper.make_node("Slice", ["cells", "second_start", "second_end"], ["cell_y"]),
        const("grid", np.array(float(GRID), dtype=np.float32)),
        helper.make_node("Mul", ["cell_y", "grid"], ["row_start"]),
        helper.make_node("Add", ["row_start", "cell_x"], ["flat_f"]),
        const("one_shape", np.array([1], dtype=np.int64)),
        helper.make_node("Reshape", ["flat_f", "one_shape"], ["flat_f1"]),
        helper.make_node("Cast", ["flat_f1"], ["flat"], to=TensorProto.INT64),
        # Squared distance of every cell's embedding to the clicked one.
        const("flat_shape", np.array([CHANNELS, GRID * GRID], dtype=np.int64)),
        helper.make_node("Reshape", ["image_embeddings", "flat_shape"], ["emb"]),
        helper.make_node("Gather", ["emb", "flat"], ["clicked"], axis=1),
        helper.make_node("Sub", ["emb", "clicked"], ["diff"]),
        helper.make_node("Mul", ["diff", "diff"], ["diff2"]),
        const("channel_axis", np.array([0], dtype=np.int64)),
        helper.make_node("ReduceSum", ["diff2", "channel_axis"], ["dist2"], keepdims=1),
        const("taus", np.array(TAUS, dtype=np.float32).reshape(n, 1)),
        helper.make_node("Sub", ["taus", "dist2"], ["logits_flat"]),
        # Prompts this toy ignores still feed the graph (0 × their sum).
        helper.make_node("ReduceSum", ["mask_input"], ["mask_sum"], keepdims=0),
        helper.make_node("Mul", ["mask_sum", "has_mask_input"], ["mask_term"]),
        helper.make_node("Cast", ["point_labels"], ["labels_f"], to=TensorProto.FLOAT),
        helper.make_node("ReduceSum", ["labels_f"], ["labels_sum"], keepdims=0),
        helper.make_node("Add", ["mask_term", "labels_sum"], ["unused_sum"]),
        helper.make_node("Mul", ["unused_sum", "zero"], ["unused"]),
        helper.make_node("Add", ["logits_flat", "unused"], ["logits_flat2"]),
        const("grid_shape", np.array([1, n, GRID, GRID], dtype=np.int64)),
        helper.make_node("Reshape", ["logits_flat2", "grid_shape"], ["logits"]),
        # low_res_masks: 64 -> 256.
        const("x4", np.array([1, 1, 4, 4], dtype=np.float32)),
        helper.make_node("Resize", ["logits", "", "x4"], ["low_res_masks"], mode="linear"),
        # masks: 64 -> 1024, crop the unpadded area, resize to the original size.
        const("x16", np.array([1, 1, CELL, CELL], dtype=np.float32)),
        helper.make_node("Resize", ["logits", "", "x16"], ["up"], mode="linear"),
        helper.make_node("ReduceMax", ["orig_im_size"], ["longest"], keepdims=0),
        const("side", np.array(1024.0, dtype=np.float32)),
        helper.make_node("Div", ["side", "longest"], ["scale"]),
        helper.make_node("Mul", ["orig_im_size", "scale"], ["valid_f"]),
        const("half", np.array(0.5, dtype=np.float32)),
        helper.make_node("Add", ["valid_f", "half"], ["valid_r"]),
        helper.make_node("Floor", ["valid_r"], ["valid_floor"]),
        helper.make_node("Cast", ["valid_floor"], ["valid"], to=TensorProto.INT64),
        const("lead_dims", np.array([1, n], dtype=np.int64)),
        helper.make_node("Concat", ["lead_dims", "valid"], ["crop_end"], axis=0),
        const("crop_start", np.array([0, 0, 0, 0], dtype=np.int64)),
        helper.make_node("Slice", ["up", "crop_start", "crop_end"], ["cropped"]),
        helper.make_node("Cast", ["orig_im_size"], ["orig_i"], to=TensorProto.INT64),
        helper.make_node("Concat", ["lead_dims", "orig_i"], ["out_size"], axis=0),
        helper.make_node("Resize", ["cropped", "", "", "out_size"], ["masks"], mode="linear"),
        const("iou_predictions", np.array([IOUS], dtype=np.float32)),
    ]
    inputs = [
        helper.make_tensor_value_info("image_embeddings", TensorProto.FLOAT, [1, CHANNELS, GRID, GRID]),
        helper.make_tensor_value_info("point_coords", TensorProto.FLOAT, [1, "num_points", 2]),
        helper.make_tensor_value_info("point_labels", TensorProto.FLOAT, [1, "num_points"]),
        helper.make_tensor_value_info("mask_input", TensorProto.FLOAT, [1, 1, 256, 256]),
        helper.make_tensor_value_info("has_mask_input", TensorProto.FLOAT, [1]),
        helper.make_tensor_value_info("orig_im_size", TensorProto.FLOAT, [2]),
    ]
    outputs = [
        helper.make_tensor_value_info("masks", TensorProto.FLOAT, [1, n, "height", "width"]),
        helper.make_tensor_value_info("iou_predictions", TensorProto.FLOAT, [1, n]),
        helper.make_tensor_value_info("low_res_masks", TensorProto.FLOAT, [1, n, 256, 256]),
    ]
    graph = helper.make_graph(nodes, "tiny_sam_decoder", inputs, outputs)
    return helper.make_model(graph, opset_imports=OPSET, producer_name="opengs make_tiny_onnx")


def main():
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "common/perception/tests/fixtures")
    out.mkdir(parents=True, exist_ok=True)
    for name, model in [("tiny_sam_encoder.onnx", encoder()), ("tiny_sam_decoder.onnx", decoder())]:
        model.ir_version = 8  # opset 17 era; loadable by any ONNX Runtime >= 1.13
        onnx.checker.check_model(model, full_check=True)
        onnx.save(model, out / name)
        print(f"wrote {out / name} ({(out / name).stat().st_size} bytes)")


if __name__ == "__main__":
    main()
