#!/usr/bin/env python3
"""Tiny stand-ins for the SAM ONNX exports, with the real input/output names
and shapes, for testing the perception crate's model runners without weights.

  encoder: image[1,3,1024,1024] -> image_embeddings[1,256,64,64]
           (16x16 average pooling, then a fixed 1x1 convolution to 256 channels)
  decoder: image_embeddings[1,256,64,64], point_coords[1,N,2], point_labels[1,N],
           mask_input[1,1,256,256], has_mask_input[1], orig_im_size[2]
           -> masks[1,3,H,W], iou_predictions[1,3], low_res_masks[1,3,256,256]
           Mask k is "embedding within tau_k of the embedding under the prompt",
           the prompt being the mean of the prompt points with label >= 0 (a
           click, or the centre of a box given as corners labelled 2 and 3),
           so a prompt selects the uniformly coloured region under it.
  tagger (recognize-anything RAM/RAM++ export):
           image[1,3,384,384] -> tag[1,T]; tag t = sigmoid of the strongest
           per-pixel response to colour t (tiny_tag_list.txt: red, green and
           blue cube), so a tag fires when its colour appears anywhere.
  detector (YOLO-World export with a text-feature prompt, wkentaro/yolo-world-onnx):
           images[1,3,640,640], text_features[1,K,512] -> scores[1,N,K], boxes[1,N,4]
           N fixed candidate boxes (xyxy in the 640 letterboxed frame, see
           DET_BOXES); score = sigmoid(S * <mean colour in box, text feature> + B)
           with colours and tag embeddings (tiny_tag_embeddings.npy) in the
           same 512-d space.
  tiny_tagger_wrong_input.onnx: the tagger with its input named "img"
           (what `opengs models check` must reject).
  proposals (MobileSAMv2 object-aware model, ultralytics YOLOv8 export):
           images[1,3,640,640] -> output0[1,4+1,N]: cx,cy,w,h of N fixed boxes
           (PROPOSAL_BOXES) and an objectness = sigmoid of the mean colour
           saturation inside the box.

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
        # Prompt = mean of the points with label >= 0 (the SAM padding point
        # has label -1; a box is two corners labelled 2 and 3).
        const("label_floor", np.array(-0.5, dtype=np.float32)),
        helper.make_node("Greater", ["point_labels", "label_floor"], ["used_b"]),
        helper.make_node("Cast", ["used_b"], ["used"], to=TensorProto.FLOAT),
        const("last_axis", np.array([2], dtype=np.int64)),
        helper.make_node("Unsqueeze", ["used", "last_axis"], ["used3"]),
        helper.make_node("Mul", ["point_coords", "used3"], ["weighted"]),
        const("point_axis", np.array([1], dtype=np.int64)),
        helper.make_node("ReduceSum", ["weighted", "point_axis"], ["coord_sum"], keepdims=1),
        helper.make_node("ReduceSum", ["used3", "point_axis"], ["used_sum"], keepdims=1),
        const("one", np.array(1.0, dtype=np.float32)),
        helper.make_node("Max", ["used_sum", "one"], ["used_count"]),
        helper.make_node("Div", ["coord_sum", "used_count"], ["prompt"]),
        # Embedding cell under the prompt (coordinates in the 1024 frame).
        const("cell_size", np.array(float(CELL), dtype=np.float32)),
        const("grid_max", np.array(float(GRID - 1), dtype=np.float32)),
        const("zero", np.array(0.0, dtype=np.float32)),
        const("first_start", np.array([0, 0, 0], dtype=np.int64)),
        const("first_end", np.array([1, 1, 1], dtype=np.int64)),
        const("second_start", np.array([0, 0, 1], dtype=np.int64)),
        const("second_end", np.array([1, 1, 2], dtype=np.int64)),
        helper.make_node("Div", ["prompt", "cell_size"], ["cells_f"]),
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



# --- ensemble and MobileSAMv2 stand-ins -------------------------------------

TAGS = ["red cube", "green cube", "blue cube"]
TAG_COLOURS = np.array([[220, 30, 30], [30, 200, 40], [40, 50, 210]], dtype=np.float32)
TAG_SIDE = 384
IMAGENET_MEAN = np.array([0.485, 0.456, 0.406], dtype=np.float32)
IMAGENET_STD = np.array([0.229, 0.224, 0.225], dtype=np.float32)
YOLO_SIDE = 640
YOLO_CELL = 16  # pooling cell of the toy detectors
YOLO_GRID = YOLO_SIDE // YOLO_CELL
TEXT_DIM = 512
# Candidate boxes (x0, y0, x1, y1) in the 640 letterboxed frame. The tests'
# 160x120 image is scaled by 4 and padded by 80 rows on top: its red square
# [20,60)x[30,70) is [80,240)x[200,360) here, its green square
# [100,140)x[40,80) is [400,560)x[240,400).
DET_BOXES = np.array(
    [
        [76, 196, 244, 364],  # tight around the red square (IoU ~0.91 with it)
        [400, 240, 640, 480],  # green square plus background (IoU 0.44)
        [0, 80, 160, 240],  # background
        [480, 80, 640, 200],  # background
        [0, 0, 640, 80],  # letterbox padding
    ],
    dtype=np.float32,
)
DET_SCALE, DET_BIAS = 20.0, -4.0
PROPOSAL_BOXES = np.array(
    [
        [76, 196, 244, 364],  # red square
        [78, 198, 242, 362],  # near-duplicate of the first (NMS drops it)
        [396, 236, 564, 404],  # green square
        [0, 80, 160, 240],  # background
        [480, 80, 640, 200],  # background
    ],
    dtype=np.float32,
)
PROP_SCALE, PROP_BIAS = 20.0, -5.0


def colour_basis():
    """Orthonormal 512x3 map from centred RGB to the shared 'text' space."""
    rng = np.random.default_rng(1)
    q, _ = np.linalg.qr(rng.standard_normal((TEXT_DIM, 3)))
    return q.astype(np.float32)


def tag_embeddings():
    """Unit text features of TAGS: the tag colour's direction in the shared space."""
    centred = TAG_COLOURS / 255.0 - 0.5
    units = centred / np.linalg.norm(centred, axis=1, keepdims=True)
    return (units @ colour_basis().T).astype(np.float32)


def tagger(input_name="image"):
    # Per-pixel response of tag t: 2 * (+1 on its channel, -1 on the others) . x - 4,
    # on ImageNet-normalised input; the strongest pixel decides.
    weight = (2.0 * (2.0 * np.eye(3) - 1.0)).reshape(3, 3, 1, 1).astype(np.float32)
    bias = np.full(3, -4.0, dtype=np.float32)
    nodes = [
        helper.make_node("Conv", [input_name, "weight", "bias"], ["response"]),
        helper.make_node("GlobalMaxPool", ["response"], ["strongest"]),
        const("flat", np.array([1, len(TAGS)], dtype=np.int64)),
        helper.make_node("Reshape", ["strongest", "flat"], ["logits"]),
        helper.make_node("Sigmoid", ["logits"], ["tag"]),
    ]
    graph = helper.make_graph(
        nodes,
        "tiny_tagger",
        [helper.make_tensor_value_info(input_name, TensorProto.FLOAT, [1, 3, TAG_SIDE, TAG_SIDE])],
        [helper.make_tensor_value_info("tag", TensorProto.FLOAT, [1, len(TAGS)])],
        [numpy_helper.from_array(weight, "weight"), numpy_helper.from_array(bias, "bias")],
    )
    return helper.make_model(graph, opset_imports=OPSET, producer_name="opengs make_tiny_onnx")


def box_average(boxes):
    """[G*G, N] matrix averaging the pooled cells whose centre lies in each box."""
    centres = (np.arange(YOLO_GRID, dtype=np.float32) + 0.5) * YOLO_CELL
    cx, cy = np.meshgrid(centres, centres)  # row-major cells
    cx, cy = cx.reshape(-1), cy.reshape(-1)
    cols = []
    for x0, y0, x1, y1 in boxes:
        inside = ((cx >= x0) & (cx < x1) & (cy >= y0) & (cy < y1)).astype(np.float32)
        cols.append(inside / max(inside.sum(), 1.0))
    return np.stack(cols, axis=1).astype(np.float32)


def pooled_cells(nodes, source, channels, name):
    """AveragePool the 640 input to 16-pixel cells, flattened to [channels, G*G]."""
    nodes += [
        helper.make_node("AveragePool", [source], [name + "_pool"], kernel_shape=[YOLO_CELL] * 2, strides=[YOLO_CELL] * 2),
        const(name + "_shape", np.array([channels, YOLO_GRID * YOLO_GRID], dtype=np.int64)),
        helper.make_node("Reshape", [name + "_pool", name + "_shape"], [name]),
    ]


def detector():
    n = len(DET_BOXES)
    nodes = []
    pooled_cells(nodes, "images", 3, "cells")
    nodes += [
        const("half", np.array(0.5, dtype=np.float32)),
        helper.make_node("Sub", ["cells", "half"], ["centred"]),
        const("average", box_average(DET_BOXES)),
        helper.make_node("MatMul", ["centred", "average"], ["box_colour_t"]),  # [3, N]
        helper.make_node("Transpose", ["box_colour_t"], ["box_colour"], perm=[1, 0]),
        const("basis_t", colour_basis().T.copy()),
        helper.make_node("MatMul", ["box_colour", "basis_t"], ["box_embed"]),  # [N, 512]
        const("batch_axis", np.array([0], dtype=np.int64)),
        helper.make_node("Squeeze", ["text_features", "batch_axis"], ["text"]),  # [K, 512]
        helper.make_node("Transpose", ["text"], ["text_t"], perm=[1, 0]),
        helper.make_node("MatMul", ["box_embed", "text_t"], ["similarity"]),  # [N, K]
        const("det_scale", np.array(DET_SCALE, dtype=np.float32)),
        const("det_bias", np.array(DET_BIAS, dtype=np.float32)),
        helper.make_node("Mul", ["similarity", "det_scale"], ["scaled"]),
        helper.make_node("Add", ["scaled", "det_bias"], ["logits"]),
        helper.make_node("Sigmoid", ["logits"], ["probs"]),
        helper.make_node("Unsqueeze", ["probs", "batch_axis"], ["scores"]),
        const("boxes", DET_BOXES.reshape(1, n, 4)),
    ]
    inputs = [
        helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, YOLO_SIDE, YOLO_SIDE]),
        helper.make_tensor_value_info("text_features", TensorProto.FLOAT, [1, "num_classes", TEXT_DIM]),
    ]
    outputs = [
        helper.make_tensor_value_info("scores", TensorProto.FLOAT, [1, n, "num_classes"]),
        helper.make_tensor_value_info("boxes", TensorProto.FLOAT, [1, n, 4]),
    ]
    graph = helper.make_graph(nodes, "tiny_yolo_world", inputs, outputs)
    return helper.make_model(graph, opset_imports=OPSET, producer_name="opengs make_tiny_onnx")


def proposals():
    n = len(PROPOSAL_BOXES)
    x0, y0, x1, y1 = PROPOSAL_BOXES.T
    cxcywh = np.stack([(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0]).reshape(1, 4, n).astype(np.float32)
    nodes = [
        helper.make_node("ReduceMax", ["images"], ["brightest"], axes=[1], keepdims=1),
        helper.make_node("ReduceMin", ["images"], ["darkest"], axes=[1], keepdims=1),
        helper.make_node("Sub", ["brightest", "darkest"], ["saturation"]),
    ]
    pooled_cells(nodes, "saturation", 1, "cells")
    nodes += [
        const("average", box_average(PROPOSAL_BOXES)),
        helper.make_node("MatMul", ["cells", "average"], ["box_saturation"]),  # [1, N]
        const("prop_scale", np.array(PROP_SCALE, dtype=np.float32)),
        const("prop_bias", np.array(PROP_BIAS, dtype=np.float32)),
        helper.make_node("Mul", ["box_saturation", "prop_scale"], ["scaled"]),
        helper.make_node("Add", ["scaled", "prop_bias"], ["logits"]),
        helper.make_node("Sigmoid", ["logits"], ["objectness"]),
        const("score_shape", np.array([1, 1, n], dtype=np.int64)),
        helper.make_node("Reshape", ["objectness", "score_shape"], ["score_row"]),
        const("box_rows", cxcywh),
        helper.make_node("Concat", ["box_rows", "score_row"], ["output0"], axis=1),
    ]
    graph = helper.make_graph(
        nodes,
        "tiny_object_aware_yolov8",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, YOLO_SIDE, YOLO_SIDE])],
        [helper.make_tensor_value_info("output0", TensorProto.FLOAT, [1, 5, n])],
    )
    return helper.make_model(graph, opset_imports=OPSET, producer_name="opengs make_tiny_onnx")


def main():
    out = Path(sys.argv[1] if len(sys.argv) > 1 else "common/perception/tests/fixtures")
    out.mkdir(parents=True, exist_ok=True)
    models = [
        ("tiny_sam_encoder.onnx", encoder()),
        ("tiny_sam_decoder.onnx", decoder()),
        ("tiny_tagger.onnx", tagger()),
        ("tiny_detector.onnx", detector()),
        ("tiny_proposals.onnx", proposals()),
        # For `models check`: a tagger whose input is misnamed ("img", not "image").
        ("tiny_tagger_wrong_input.onnx", tagger(input_name="img")),
    ]
    for name, model in models:
        model.ir_version = 8  # opset 17 era; loadable by any ONNX Runtime >= 1.13
        onnx.checker.check_model(model, full_check=True)
        onnx.save(model, out / name)
        print(f"wrote {out / name} ({(out / name).stat().st_size} bytes)")
    (out / "tiny_tag_list.txt").write_text("".join(t + "\n" for t in TAGS))
    np.save(out / "tiny_tag_embeddings.npy", tag_embeddings())
    print(f"wrote {out / 'tiny_tag_list.txt'} and {out / 'tiny_tag_embeddings.npy'}")


if __name__ == "__main__":
    main()
