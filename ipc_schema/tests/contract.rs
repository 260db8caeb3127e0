//! Round trip of every message and rejection of every kind of malformed header.

use opengs_ipc_schema::*;

fn buffer(len: usize) -> Vec<u64> {
    aligned_buffer(len)
}

fn bytes(buf: &mut [u64], len: usize) -> &mut [u8] {
    &mut bytemuck::cast_slice_mut::<u64, u8>(buf)[..len]
}

fn stamp() -> Stamp {
    Stamp::new(MessageKind::Frame, 42, 1_000, 2_000)
}

fn frame(w: u32, h: u32, labels: bool) -> (FrameHeader, Vec<u16>, Vec<u16>, Vec<u8>) {
    let n = (w * h) as usize;
    let depth: Vec<u16> = (0..n).map(|i| (i * 7 % 65_000) as u16).collect();
    let lab: Vec<u16> = (0..n).map(|i| (i % 13) as u16).collect();
    let rgb: Vec<u8> = (0..3 * n).map(|i| (i * 31 % 251) as u8).collect();
    let hdr = FrameHeader::new(
        stamp(),
        w,
        h,
        5000.0,
        [525.0, 525.0, 319.5, 239.5],
        Some([1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0]),
        labels,
        7,
    );
    (hdr, depth, lab, rgb)
}

#[test]
fn frame_round_trip_with_and_without_labels() {
    for with_labels in [false, true] {
        // Odd sizes exercise section padding.
        let (hdr, depth, lab, rgb) = frame(13, 7, with_labels);
        let mut buf = buffer(hdr.payload_len());
        let payload = bytes(&mut buf, hdr.payload_len());
        let parts = FrameParts {
            depth: &depth,
            labels: with_labels.then_some(&lab[..]),
            rgb: &rgb,
        };
        hdr.encode(&parts, as_uninit_mut(payload)).expect("encode");
        let view = hdr.decode(payload).expect("decode");
        assert_eq!(view.depth, &depth[..]);
        assert_eq!(view.rgb, &rgb[..]);
        assert_eq!(view.labels, with_labels.then_some(&lab[..]));
        assert_eq!(view.header.stamp.seq, 42);
        assert!(view.header.has_gt());
        assert_eq!(view.header.gt_pose[2], 3.0);
    }
}

#[test]
fn frame_malformed_headers_rejected() {
    let (hdr, depth, _, rgb) = frame(8, 4, false);
    let mut buf = buffer(hdr.payload_len());
    let payload = bytes(&mut buf, hdr.payload_len());
    hdr.encode(
        &FrameParts {
            depth: &depth,
            labels: None,
            rgb: &rgb,
        },
        as_uninit_mut(payload),
    )
    .expect("encode");
    let payload: &[u8] = payload;

    let mut bad = hdr;
    bad.stamp.version = 99;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::Version { found: 99, .. })
    ));
    let mut bad = hdr;
    bad.stamp.kind = MessageKind::Pose as u32;
    assert!(matches!(bad.decode(payload), Err(SchemaError::Kind { .. })));
    let mut bad = hdr;
    bad.stamp.payload_len += 8;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::PayloadLength { .. })
    ));
    let mut bad = hdr;
    bad.width = 9; // dimensions disagree with the payload
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::LayoutMismatch { .. })
    ));
    let mut bad = hdr;
    bad.width = 0;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::Dimensions { .. })
    ));
    let mut bad = hdr;
    bad.height = 100_000;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::Dimensions { .. })
    ));
    let mut bad = hdr;
    bad.depth_scale = f32::NAN;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::NonFinite("depth_scale"))
    ));
    let mut bad = hdr;
    bad.gt_pose[0] = f64::INFINITY;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::NonFinite("gt_pose"))
    ));
    // The last-frame mark changes no plane; a flag nobody defined is refused.
    let last = hdr.last();
    assert!(last.is_last() && !hdr.is_last());
    assert_eq!(last.decode(payload).expect("last frame").depth, &depth[..]);
    let mut bad = hdr;
    bad.flags |= 8;
    assert!(matches!(bad.decode(payload), Err(SchemaError::Invalid(_))));
    let mut bad = hdr;
    bad.flags |= FrameHeader::HAS_LABELS; // claims a labels plane that is not there
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::LayoutMismatch { .. })
    ));
    // A truncated payload.
    assert!(matches!(
        hdr.decode(&payload[..payload.len() - 8]),
        Err(SchemaError::PayloadLength { .. })
    ));
    // Planes that do not match the header are refused at encode time.
    let mut buf2 = buffer(hdr.payload_len());
    let p2 = bytes(&mut buf2, hdr.payload_len());
    assert!(hdr
        .encode(
            &FrameParts {
                depth: &depth[1..],
                labels: None,
                rgb: &rgb
            },
            as_uninit_mut(p2)
        )
        .is_err());
}

#[test]
fn pose_round_trip_and_rejects() {
    let h = PoseHeader {
        stamp: Stamp::new(MessageKind::Pose, 3, 0, 0),
        pose: [0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0],
        gt_pose: [0.0; 7],
        has_gt: 0,
        status: PoseStatus::Tracked as u32,
        is_keyframe: 1,
        iterations: 5,
        inliers: 900,
        overlap: 0.9,
    };
    assert_eq!(h.decode(&[]), Ok(PoseStatus::Tracked));
    let mut bad = h;
    bad.status = 77;
    assert!(bad.decode(&[]).is_err());
    let mut bad = h;
    bad.pose[6] = f64::NAN;
    assert_eq!(bad.decode(&[]), Err(SchemaError::NonFinite("pose")));
    let mut bad = h;
    bad.overlap = 1.5;
    assert!(bad.decode(&[]).is_err());
    let mut bad = h;
    bad.stamp.version = 0;
    assert!(matches!(bad.decode(&[]), Err(SchemaError::Version { .. })));
    assert!(matches!(
        h.decode(&[0u8; 8]),
        Err(SchemaError::PayloadLength { .. })
    ));
}

#[test]
fn keyframe_round_trip_and_rejects() {
    let (w, h) = (5u32, 3u32);
    let n = 15;
    let points = vec![[1.0f32, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.5]];
    let covs = vec![[1.0f32, 0.0, 0.0, 1.0, 0.0, 1.0]; 3];
    let depth = vec![1234u16; n];
    let labels: Vec<u16> = (0..n as u16).collect();
    let rgb = vec![9u8; 3 * n];
    let hdr = KeyframeHeader::new(
        stamp(),
        [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0],
        [10.0, 10.0, 2.0, 1.0],
        w,
        h,
        5000.0,
        3,
        true,
        11,
    );
    let mut buf = buffer(hdr.payload_len());
    let payload = bytes(&mut buf, hdr.payload_len());
    hdr.encode(
        &KeyframeParts {
            points: &points,
            covariances: &covs,
            depth: &depth,
            labels: Some(&labels),
            rgb: &rgb,
        },
        as_uninit_mut(payload),
    )
    .expect("encode");
    let v = hdr.decode(payload).expect("decode");
    assert_eq!(v.points, &points[..]);
    assert_eq!(v.covariances, &covs[..]);
    assert_eq!(v.depth, &depth[..]);
    assert_eq!(v.labels, Some(&labels[..]));
    assert_eq!(v.rgb, &rgb[..]);
    let mut bad = hdr;
    bad.flags = 0; // claims no labels plane, but one is there
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::LayoutMismatch { .. })
    ));
    let mut bad = hdr;
    bad.flags = 6;
    assert!(matches!(bad.decode(payload), Err(SchemaError::Invalid(_))));
    let mut bad = hdr;
    bad.point_count = 4;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::LayoutMismatch { .. })
    ));
    let mut bad = hdr;
    bad.point_count = u32::MAX;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::Count {
            what: "point_count",
            ..
        })
    ));
    let mut bad = hdr;
    bad.pose[0] = f64::NAN;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::NonFinite(_))
    ));
    let mut bad = hdr;
    bad.stamp.kind = MessageKind::Frame as u32;
    assert!(matches!(bad.decode(payload), Err(SchemaError::Kind { .. })));
}

#[test]
fn segments_round_trip_and_rejects() {
    let map: Vec<u32> = (0..12).map(|i| i % 3).collect();
    let labels = vec![
        SegmentLabel::new(1, 0.9, Some("chair"), 0.7),
        SegmentLabel::new(2, 0.5, None, 0.0),
    ];
    let hdr = SegmentsHeader::new(stamp(), 4, 3, 2, 0);
    let mut buf = buffer(hdr.payload_len());
    let payload = bytes(&mut buf, hdr.payload_len());
    hdr.encode(&map, &labels, as_uninit_mut(payload))
        .expect("encode");
    let v = hdr.decode(payload).expect("decode");
    assert_eq!(v.label_map, &map[..]);
    assert_eq!(v.labels[0].class(), Some("chair"));
    assert_eq!(v.labels[1].class(), None);
    let mut bad = hdr;
    bad.label_count = 3;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::LayoutMismatch { .. })
    ));
    let mut bad = hdr;
    bad.label_count = 1 << 30;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::Count { .. })
    ));
    // Long class names truncate on a char boundary.
    let long = SegmentLabel::new(3, 1.0, Some(&"é".repeat(40)), 1.0);
    assert_eq!(long.class().map(|c| c.chars().count()), Some(18));
}

#[test]
fn render_round_trip_and_rejects() {
    let map = vec![5u32; 6];
    let labels = vec![LabelCompleteness {
        label: 5,
        visible: 10,
        total: 20,
    }];
    let hdr = RenderHeader::new(stamp(), 3, 2, 1);
    let mut buf = buffer(hdr.payload_len());
    let payload = bytes(&mut buf, hdr.payload_len());
    hdr.encode(&map, &labels, as_uninit_mut(payload))
        .expect("encode");
    let v = hdr.decode(payload).expect("decode");
    assert_eq!(v.labels, &labels[..]);
    assert_eq!(v.label_map, &map[..]);
    // visible > total is nonsense.
    let bad_labels = vec![LabelCompleteness {
        label: 5,
        visible: 30,
        total: 20,
    }];
    hdr.encode(&map, &bad_labels, as_uninit_mut(payload))
        .expect("encode");
    assert!(matches!(hdr.decode(payload), Err(SchemaError::Invalid(_))));
    let mut bad = hdr;
    bad.height = 3;
    assert!(bad.decode(payload).is_err());
}

#[test]
fn consensus_round_trip_and_rejects() {
    let label_map = vec![1u32, 1, 2, 2, 0, 3];
    let mapping = [[10u32, 1], [11, 2]];
    let relabels = [PixelRun {
        from: 7,
        to: 2,
        offset: 0,
        count: 2,
        scope: PixelRun::SCOPE_PIXELS,
    }];
    let prunes = [PruneRun {
        label: 1,
        offset: 2,
        count: 1,
    }];
    let pixels = [2u32, 3, 5];
    let parts = ConsensusResult {
        label_map: &label_map,
        mapping: &mapping,
        relabels: &relabels,
        prunes: &prunes,
        pixels: &pixels,
    };
    let hdr = ConsensusHeader::new(stamp(), 3, 2, 0.1, &parts);
    let mut buf = buffer(hdr.payload_len());
    let payload = bytes(&mut buf, hdr.payload_len());
    hdr.encode(&parts, as_uninit_mut(payload)).expect("encode");
    let v = hdr.decode(payload).expect("decode");
    assert_eq!(v.header.counter_prune_scale, 0.1);
    assert_eq!(v.result.mapping, &mapping[..]);
    assert_eq!(v.result.relabels, &relabels[..]);
    assert_eq!(v.result.prunes, &prunes[..]);
    assert_eq!(v.result.pixels, &pixels[..]);
    // A run that points past the pixel list, and a pixel outside the image.
    let bad_runs = [PixelRun {
        from: 7,
        to: 2,
        offset: 2,
        count: 5,
        scope: PixelRun::SCOPE_PIXELS,
    }];
    let bad = ConsensusResult {
        relabels: &bad_runs,
        ..parts
    };
    assert!(hdr.encode(&bad, as_uninit_mut(payload)).is_err());
    // A relabel scope that is none of pixels, label, merged, rejoin: refused on encode and decode.
    let bad_scope = [PixelRun {
        scope: 4,
        ..relabels[0]
    }];
    let bad = ConsensusResult {
        relabels: &bad_scope,
        ..parts
    };
    assert!(hdr.encode(&bad, as_uninit_mut(payload)).is_err());
    hdr.encode(&parts, as_uninit_mut(payload)).expect("encode");
    // label map 6·4 + mapping 2·8 bytes, then the run's from, to, offset, count, scope.
    payload[56..60].copy_from_slice(&4u32.to_ne_bytes());
    assert!(matches!(hdr.decode(payload), Err(SchemaError::Invalid(_))));
    for scope in [
        PixelRun::SCOPE_LABEL,
        PixelRun::SCOPE_MERGED,
        PixelRun::SCOPE_REJOIN,
    ] {
        payload[56..60].copy_from_slice(&scope.to_ne_bytes());
        assert_eq!(
            hdr.decode(payload).expect("decode").result.relabels[0].scope,
            scope
        );
    }
    hdr.encode(&parts, as_uninit_mut(payload)).expect("encode");
    let bad_pixels = [2u32, 3, 6];
    let bad = ConsensusResult {
        label_map: &label_map,
        mapping: &mapping,
        relabels: &relabels,
        prunes: &prunes,
        pixels: &bad_pixels,
    };
    assert!(hdr.encode(&bad, as_uninit_mut(payload)).is_err());
    let mut h2 = hdr;
    h2.mapping_count = 3;
    assert!(h2.decode(payload).is_err());
    // θ must be a length.
    for theta in [0.0, -0.1, f32::NAN, f32::INFINITY] {
        let mut h3 = hdr;
        h3.counter_prune_scale = theta;
        assert!(
            matches!(h3.decode(payload), Err(SchemaError::Invalid(_))),
            "θ = {theta}"
        );
    }
}

#[test]
fn map_target_round_trip_and_rejects() {
    let means = [[0.0f32, 1.0, 2.0]; 4];
    let rots = [[1.0f32, 0.0, 0.0, 0.0]; 4];
    let scales = [[0.01f32, 0.02, 0.03]; 4];
    let hdr = MapTargetHeader::new(stamp(), 4, 2);
    let mut buf = buffer(hdr.payload_len());
    let payload = bytes(&mut buf, hdr.payload_len());
    hdr.encode(
        &MapTargetParts {
            means: &means,
            rotations: &rots,
            scales: &scales,
        },
        as_uninit_mut(payload),
    )
    .expect("encode");
    let v = hdr.decode(payload).expect("decode");
    assert_eq!(v.scales, &scales[..]);
    let mut bad = hdr;
    bad.count = 5;
    assert!(bad.decode(payload).is_err());
}

#[test]
fn telemetry_round_trip_and_rejects() {
    let input = Stamp::new(MessageKind::Frame, 9, 0, 100);
    let t = TelemetryHeader::new("tracker", TelemetryEvent::Processed, &input, 100, 150, 400);
    assert_eq!(t.decode(&[]), Ok(TelemetryEvent::Processed));
    assert_eq!(t.stage_name(), "tracker");
    assert_eq!(t.stamp.seq, 9);
    let mut bad = t;
    bad.end_ns = 120; // ends before it starts
    assert!(bad.decode(&[]).is_err());
    let mut bad = t;
    bad.event = 0;
    assert!(bad.decode(&[]).is_err());
    let mut bad = t;
    bad.stage = [0; 16];
    assert!(bad.decode(&[]).is_err());
    let p = TelemetryHeader::progress("mapper", 120, 500, 1000);
    assert_eq!(p.decode(&[]), Ok(TelemetryEvent::Progress));
    assert_eq!((p.work_done, p.work_total), (120, 500));
    let mut bad = p;
    bad.work_done = 501;
    assert!(bad.decode(&[]).is_err());
}

#[test]
fn control_round_trip_and_rejects() {
    let text = "segmenter prior";
    let hdr = ControlHeader::new(ControlCommand::Swap, 5, true, text);
    let mut buf = buffer(hdr.payload_len());
    let payload = bytes(&mut buf, hdr.payload_len());
    hdr.encode(text, as_uninit_mut(payload)).expect("encode");
    let v = hdr.decode(payload).expect("decode");
    assert_eq!(
        v,
        ControlView {
            command: ControlCommand::Swap,
            ok: true,
            request_id: 5,
            text
        }
    );
    let mut bad = hdr;
    bad.command = 55;
    assert!(bad.decode(payload).is_err());
    let mut bad = hdr;
    bad.text_len = 1 << 40;
    assert!(matches!(
        bad.decode(payload),
        Err(SchemaError::Count { .. })
    ));
    payload[0] = 0xff; // invalid UTF-8
    assert!(hdr.decode(payload).is_err());
}

#[test]
fn misaligned_payload_rejected() {
    let (hdr, depth, _, rgb) = frame(4, 2, false);
    let mut buf = buffer(hdr.payload_len() + 8);
    let all = bytemuck::cast_slice_mut::<u64, u8>(&mut buf);
    hdr.encode(
        &FrameParts {
            depth: &depth,
            labels: None,
            rgb: &rgb,
        },
        as_uninit_mut(&mut all[..hdr.payload_len()]),
    )
    .expect("encode");
    let shifted = &all[1..1 + hdr.payload_len()];
    assert_eq!(hdr.decode(shifted).err(), Some(SchemaError::Alignment(8)));
}

#[test]
fn consensus_with_many_runs_fills_its_payload() {
    let label_map = vec![0u32; 640 * 480];
    let mapping: Vec<[u32; 2]> = (0..14).map(|i| [i, i + 1]).collect();
    let pixels: Vec<u32> = (0..1001).collect();
    for (r, p) in [(0usize, 0usize), (1, 1), (3, 2), (2, 3), (5, 5)] {
        let relabels: Vec<PixelRun> = (0..r)
            .map(|i| PixelRun {
                from: 1,
                to: 2,
                offset: i as u32,
                count: 1,
                scope: PixelRun::SCOPE_PIXELS,
            })
            .collect();
        let prunes: Vec<PruneRun> = (0..p)
            .map(|i| PruneRun {
                label: 1,
                offset: i as u32,
                count: 3,
            })
            .collect();
        let parts = ConsensusResult {
            label_map: &label_map,
            mapping: &mapping,
            relabels: &relabels,
            prunes: &prunes,
            pixels: &pixels,
        };
        let hdr = ConsensusHeader::new(stamp(), 640, 480, 0.1, &parts);
        let mut buf = buffer(hdr.payload_len());
        let payload = bytes(&mut buf, hdr.payload_len());
        hdr.encode(&parts, as_uninit_mut(payload))
            .unwrap_or_else(|e| panic!("{r} relabels, {p} prunes: {e}"));
        let v = hdr.decode(payload).expect("decode");
        assert_eq!(v.result.prunes, &prunes[..]);
        assert_eq!(v.result.relabels, &relabels[..]);
    }
}
