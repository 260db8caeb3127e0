#!/usr/bin/env python3
"""Converts a TUM RGB-D folder into a ROS 2 bag (MCAP) that `opengs run --dataset
rosbag2:BAG` reads, using the pure-Python `rosbags` package (no ROS install):

    scripts/setup-python.sh            # prints the python of .venv/ with rosbags and pillow
    .venv/bin/python scripts/tum_to_rosbag2.py TUM_DIR BAG_DIR [options]

Reads rgb.txt, depth.txt (16-bit PNGs, --depth-scale units per metre, 5000 for TUM),
groundtruth.txt when present, and the camera from intrinsics.txt (`fx fy cx cy width
height`, what `opengs synth` writes), else --intrinsics, else the TUM calibration the folder
name implies (freiburg1/2/3), else 525 525 319.5 239.5. Writes, each image with its own
timestamp from the lists (header stamp = log time):

  /camera/color/image_raw        sensor_msgs/msg/Image rgb8
  /camera/depth/image_rect_raw   sensor_msgs/msg/Image 32FC1 in metres (exact for TUM's
                                 5000 units/m), or 16UC1 in mm with --depth-encoding 16UC1
  /camera/color/camera_info      sensor_msgs/msg/CameraInfo, with each colour image
  /groundtruth/pose              geometry_msgs/msg/PoseStamped, every groundtruth.txt line

Labels (labels.txt) are not converted. --compress writes zstd-compressed MCAP chunks.
"""

import argparse
import sys
from decimal import Decimal
from pathlib import Path

import numpy as np
from PIL import Image as PilImage
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
from rosbags.typesys import Stores, get_typestore

TS = get_typestore(Stores.ROS2_HUMBLE)
T = TS.types
CAMERA_FRAME = "camera_color_optical_frame"

TUM_CAMERAS = {
    ("freiburg1", "fr1"): (517.3, 516.5, 318.6, 255.3),
    ("freiburg2", "fr2"): (520.9, 521.0, 325.1, 249.7),
    ("freiburg3", "fr3"): (535.4, 539.2, 320.1, 247.6),
}


def fail(msg):
    sys.exit(f"tum_to_rosbag2: {msg}")


def data_lines(path):
    """(line number, fields) of the non-comment lines of a TUM list."""
    out = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if line and not line.startswith("#"):
            out.append((n, line.split()))
    return out


def nanoseconds(text, path, n):
    try:
        return int((Decimal(text) * 1_000_000_000).to_integral_value())
    except Exception:
        fail(f"{path}:{n}: '{text}' is not a timestamp")


def file_list(folder, name):
    path = folder / name
    if not path.is_file():
        fail(f"{path}: not found")
    items = []
    for n, fields in data_lines(path):
        if len(fields) < 2:
            fail(f"{path}:{n}: expected 'timestamp filename'")
        items.append((nanoseconds(fields[0], path, n), folder / fields[1]))
    if not items:
        fail(f"{path}: lists no images")
    return sorted(items, key=lambda x: x[0])


def camera(folder, given):
    path = folder / "intrinsics.txt"
    if given:
        return [float(v) for v in given.split()] + [None, None]
    if path.is_file():
        lines = data_lines(path)
        if not lines or len(lines[0][1]) != 6:
            fail(f"{path}: expected 'fx fy cx cy width height'")
        v = lines[0][1]
        return [float(x) for x in v[:4]] + [int(float(v[4])), int(float(v[5]))]
    name = folder.resolve().name.lower()
    for keys, k in TUM_CAMERAS.items():
        if any(key in name for key in keys):
            return list(k) + [None, None]
    return [525.0, 525.0, 319.5, 239.5, None, None]


def stamp(ns):
    return T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def header(ns, frame=CAMERA_FRAME):
    return T["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame)


def image(ns, encoding, array, bpp):
    h, w = array.shape[:2]
    data = np.ascontiguousarray(array).view(np.uint8).reshape(-1)
    return T["sensor_msgs/msg/Image"](header=header(ns), height=h, width=w, encoding=encoding,
                                      is_bigendian=0, step=w * bpp, data=data)


def camera_info(ns, k, w, h):
    fx, fy, cx, cy = k[:4]
    return T["sensor_msgs/msg/CameraInfo"](
        header=header(ns), height=h, width=w, distortion_model="plumb_bob", d=np.zeros(5),
        k=np.array([fx, 0, cx, 0, fy, cy, 0, 0, 1], dtype=np.float64), r=np.eye(3).reshape(9),
        p=np.array([fx, 0, cx, 0, 0, fy, cy, 0, 0, 0, 1, 0], dtype=np.float64), binning_x=0,
        binning_y=0,
        roi=T["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0,
                                                 do_rectify=False))


def pose_stamped(ns, v):
    g = "geometry_msgs/msg/"
    pose = T[g + "Pose"](position=T[g + "Point"](x=v[0], y=v[1], z=v[2]),
                         orientation=T[g + "Quaternion"](x=v[3], y=v[4], z=v[5], w=v[6]))
    return T[g + "PoseStamped"](header=header(ns, "world"), pose=pose)


def read_rgb(path):
    try:
        return np.asarray(PilImage.open(path).convert("RGB"), dtype=np.uint8)
    except Exception as e:
        fail(f"{path}: {e}")


def read_depth(path):
    try:
        img = PilImage.open(path)
        if img.mode not in ("I;16", "I;16B", "I;16L", "I"):
            fail(f"{path}: a {img.mode} image, expected 16-bit depth")
        return np.asarray(img).astype(np.uint16)
    except SystemExit:
        raise
    except Exception as e:
        fail(f"{path}: {e}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("tum_dir", type=Path)
    ap.add_argument("bag_dir", type=Path, help="the bag directory to create (must not exist)")
    ap.add_argument("--depth-encoding", choices=["32FC1", "16UC1"], default="32FC1")
    ap.add_argument("--depth-scale", type=float, default=5000.0, help="depth PNG units per metre")
    ap.add_argument("--intrinsics", help='"fx fy cx cy" (overrides intrinsics.txt)')
    ap.add_argument("--compress", action="store_true", help="zstd-compressed MCAP chunks")
    args = ap.parse_args()
    folder = args.tum_dir
    if args.bag_dir.exists():
        fail(f"{args.bag_dir}: exists; give a new directory")
    rgb = file_list(folder, "rgb.txt")
    depth = file_list(folder, "depth.txt")
    gt_path = folder / "groundtruth.txt"
    gt = []
    if gt_path.is_file():
        for n, fields in data_lines(gt_path):
            if len(fields) != 8:
                fail(f"{gt_path}:{n}: expected 'timestamp tx ty tz qx qy qz qw'")
            gt.append((nanoseconds(fields[0], gt_path, n), [float(x) for x in fields[1:]]))
    k = camera(folder, args.intrinsics)
    messages = [(ns, "rgb", p) for ns, p in rgb] + [(ns, "depth", p) for ns, p in depth]
    messages += [(ns, "pose", v) for ns, v in gt]
    messages.sort(key=lambda m: m[0])

    writer = Writer(args.bag_dir, version=8, storage_plugin=StoragePlugin.MCAP)
    if args.compress:
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    counts = {"rgb": 0, "depth": 0, "pose": 0}
    with writer:
        c_rgb = writer.add_connection("/camera/color/image_raw", "sensor_msgs/msg/Image", typestore=TS)
        c_depth = writer.add_connection("/camera/depth/image_rect_raw", "sensor_msgs/msg/Image", typestore=TS)
        c_info = writer.add_connection("/camera/color/camera_info", "sensor_msgs/msg/CameraInfo", typestore=TS)
        c_pose = writer.add_connection("/groundtruth/pose", "geometry_msgs/msg/PoseStamped", typestore=TS) if gt else None

        def put(conn, msg, ns):
            writer.write(conn, ns, TS.serialize_cdr(msg, conn.msgtype))

        for ns, kind, item in messages:
            if kind == "rgb":
                pixels = read_rgb(item)
                h, w = pixels.shape[:2]
                if k[4] is not None and (w, h) != (k[4], k[5]):
                    fail(f"{item}: image is {w}x{h}, the camera {k[4]}x{k[5]}")
                put(c_rgb, image(ns, "rgb8", pixels, 3), ns)
                put(c_info, camera_info(ns, k, w, h), ns)
            elif kind == "depth":
                units = read_depth(item)
                if args.depth_encoding == "32FC1":
                    m = (units.astype(np.float64) / args.depth_scale).astype(np.float32)
                    m[units == 0] = np.nan
                    put(c_depth, image(ns, "32FC1", m.astype("<f4"), 4), ns)
                else:
                    mm = np.round(units.astype(np.float64) * 1000.0 / args.depth_scale)
                    mm[mm > 65535] = 0
                    put(c_depth, image(ns, "16UC1", mm.astype("<u2"), 2), ns)
            else:
                put(c_pose, pose_stamped(ns, item), ns)
            counts[kind] += 1
    print(f"wrote {args.bag_dir}: {counts['rgb']} colour, {counts['depth']} depth "
          f"({args.depth_encoding}), {counts['pose']} ground-truth poses")


if __name__ == "__main__":
    main()
