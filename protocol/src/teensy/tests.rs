//! Unit tests of the seed 003 packets.

use super::*;

type Msg = CmdMsg<4>;

fn sample() -> Msg {
    CmdMsg {
        cmd_type: CmdType::Config,
        is_relative: 1,
        mtr_angles: [90, -90, 0x0A0A, 0],
        mtr_speed_deg_s: 30,
        mtr_accel_deg_s_s: 60,
        cmd_success: 0,
    }
}

#[test]
fn legacy_layout_is_the_c_union() {
    assert_eq!(Msg::LEN, 36);
    assert_eq!(Msg::LEGACY_LEN, 37);
    let mut b = [0u8; 37];
    assert_eq!(sample().encode_legacy(&mut b), Some(37));
    assert_eq!(b[..4], [4, 0, 0, 0]);
    assert_eq!(b[12..16], (-90i32).to_le_bytes());
    assert_eq!(b[16..20], [0x0A, 0x0A, 0, 0]); // a '\n' inside the data: why the legacy framing is fragile
    assert_eq!(b[36], b'\n');
    assert_eq!(Msg::decode_legacy(&b), Ok(sample()));
    assert_eq!(Msg::decode_legacy(&b[..36]), Err(RejectReason::Framing));
    let mut bad = b;
    bad[36] = 0;
    assert_eq!(Msg::decode_legacy(&bad), Err(RejectReason::Framing));
    bad = b;
    bad[0] = 5;
    assert_eq!(Msg::decode_legacy(&bad), Err(RejectReason::Decode));
    assert_eq!(sample().encode_legacy(&mut [0u8; 36]), None);
}

#[test]
fn robust_frame_round_trip_and_errors() {
    let mut f = [0u8; Msg::ROBUST_LEN];
    let n = sample().encode_robust(&mut f).unwrap();
    // Version 1 + CmdMsg 36, one COBS code byte, then 3 check bytes and the terminator.
    assert_eq!(n, 42);
    assert_eq!(Msg::ROBUST_LEN, 42);
    assert_eq!(f[n - 1], 0);
    assert!(f[..n - 1].iter().all(|&b| b != 0));
    assert_eq!(Msg::decode_robust(&f[..n]), Ok(sample()));
    // Corrupt a byte: the CRC, checked before COBS is undone, catches it.
    let mut g = f;
    g[10] ^= 0x01;
    assert_eq!(Msg::decode_robust(&g[..n]), Err(RejectReason::Crc));
    assert_eq!(Msg::decode_robust(&f[..n - 1]), Err(RejectReason::Framing));
    // Another motor count: the length differs.
    assert_eq!(
        CmdMsg::<3>::decode_robust(&f[..n]),
        Err(RejectReason::Framing)
    );
}

/// `S`, then the check bytes of its CRC and the terminator: a frame with a good CRC around any
/// stuffed bytes.
fn sealed(stuffed: &[u8]) -> std::vec::Vec<u8> {
    let crc = crc16::checksum(stuffed);
    // The CRC's 16 bits as 2 + 7 + 7, each byte with bit 7 set.
    let k = [
        0x80 | (crc >> 14) as u8,
        0x80 | ((crc >> 7) & 0x7F) as u8,
        0x80 | (crc & 0x7F) as u8,
    ];
    [stuffed, &k, &[0]].concat()
}

#[test]
fn robust_receiver_checks_in_order() {
    let f = robust(&sample());
    let s = &f[..Msg::ROBUST_LEN - 4];
    assert_eq!(sealed(s), f);
    // Check bytes that cannot be: bit 7 clear, or bit 2 of K0 set. Refused as Crc before the CRC
    // is compared.
    for (i, mask) in [(0, 0x80), (0, 0x04), (1, 0x80), (2, 0x80)] {
        let mut g = f.clone();
        g[s.len() + i] ^= mask;
        assert_eq!(
            Msg::decode_robust(&g),
            Err(RejectReason::Crc),
            "{i} {mask:#x}"
        );
    }
    // A good CRC over a broken COBS chain (the first code points past the block): Framing.
    let mut bad = s.to_vec();
    bad[0] = 0x7F;
    assert_eq!(
        Msg::decode_robust(&sealed(&bad)),
        Err(RejectReason::Framing)
    );
    // A zero inside S with a good CRC: Framing too (the length is still right).
    let mut bad = s.to_vec();
    bad[5] = 0;
    assert_eq!(
        Msg::decode_robust(&sealed(&bad)),
        Err(RejectReason::Framing)
    );
    // A good CRC over version 3 (the body starts 02 04 00, so S starts with the code 03, the
    // distance to that zero: 03 02 04 → 03 03 04).
    assert_eq!(s[..3], [0x03, 0x02, 0x04]);
    let mut v3 = s.to_vec();
    v3[1] = 3;
    assert_eq!(Msg::decode_robust(&sealed(&v3)), Err(RejectReason::Version));
    // A good CRC over cmd_type 5: Decode.
    let mut c5 = s.to_vec();
    c5[2] = 5;
    assert_eq!(Msg::decode_robust(&sealed(&c5)), Err(RejectReason::Decode));
}

#[test]
fn echo_carries_cmd_success() {
    let mut dec = RobustDecoder::<4>::new();
    let mut f = [0u8; Msg::ROBUST_LEN];
    let n = sample().reply(true).encode_robust(&mut f).unwrap();
    let mut got = None;
    for &b in [0u8, 0x13, 0x37, 0x00].iter().chain(&f[..n]) {
        if let Some(r) = dec.push(b) {
            got = Some(r);
        }
    }
    assert_eq!(got, Some(Ok(sample().reply(true))));
    assert_eq!(got.unwrap().unwrap().cmd_success, 1);
    assert_eq!(dec.stats().frames, 1);
    assert_eq!(dec.stats().errors, 1); // the garbage 13 37 before it
}

#[test]
fn decoder_survives_an_endless_frame() {
    let mut dec = RobustDecoder::<4>::new();
    for _ in 0..1000 {
        assert_eq!(dec.push(0x55), None);
    }
    // The last 41 bytes and the 0x00 have a frame's length, but 0x55 has bit 7 clear, so its
    // last three are no check bytes.
    assert_eq!(dec.push(0), Some(Err(RejectReason::Crc)));
    let mut f = [0u8; Msg::ROBUST_LEN];
    let n = sample().encode_robust(&mut f).unwrap();
    let results: std::vec::Vec<_> = f[..n].iter().filter_map(|&b| dec.push(b)).collect();
    assert_eq!(results, [Ok(sample())]);
}

#[test]
fn ladder_mapping() {
    let mut m = sample();
    assert_eq!(m.to_event(), None);
    m.cmd_type = CmdType::Mtrs;
    match m.to_event() {
        Some(Event::Frame(c)) => {
            // Degrees to rad, each motor to its angle under the message's 30 deg/s.
            let [a, b, ..] = c.axes;
            let cap = 30.0f32.to_radians();
            assert_eq!(
                a,
                statemachine::AxisCommand::position(core::f32::consts::FRAC_PI_2, cap)
            );
            assert_eq!(
                b,
                statemachine::AxisCommand::position(-core::f32::consts::FRAC_PI_2, cap)
            );
        }
        other => panic!("{other:?}"),
    }
}

fn robust(m: &Msg) -> std::vec::Vec<u8> {
    let mut f = [0u8; Msg::ROBUST_LEN];
    let n = m.encode_robust(&mut f).unwrap();
    f[..n].to_vec()
}

#[test]
fn a_frame_right_after_garbage_is_delivered_at_its_terminator() {
    // Non-zero garbage with no 0x00 before the frame: the frame is still the last 41 bytes before
    // its terminator (3 garbage bytes, then 42-byte frames ending at indices 3 + 41 and 44 + 42).
    let f = robust(&sample());
    let mut dec = RobustDecoder::<4>::new();
    let stream = [&[0x13, 0x37, 0x0A][..], &f, &f].concat();
    let at: std::vec::Vec<_> = stream
        .iter()
        .enumerate()
        .filter_map(|(i, &b)| dec.push(b).map(|r| (i, r)))
        .collect();
    assert_eq!(at, [(44, Ok(sample())), (86, Ok(sample()))]);
    assert_eq!(dec.stats().dropped_bytes, 3);
    assert_eq!(dec.stats().errors, 0);
    // A frame cut short, then a whole frame with no 0x00 between: the same.
    let stream = [&f[..25], &f].concat();
    let got: std::vec::Vec<_> = stream.iter().filter_map(|&b| dec.push(b)).collect();
    assert_eq!(got, [Ok(sample())]);
    assert_eq!(dec.stats().dropped_bytes, 3 + 25);
}

/// Every garbage prefix of up to 5 bytes from an alphabet of zeros, COBS codes and the frame's
/// own bytes, then a frame: alone, twice, or behind a truncated copy of itself (no 0x00 between).
/// At every byte the decoder answers as the naive reference (`verification::reference`, which
/// tries `decode_robust` on every slice ending there), and the last frame is delivered at its
/// terminator.
#[test]
fn robust_stream_holds_back_no_frame_exhaustively() {
    let f = robust(&sample());
    let alphabet = [
        0x00,
        0x01,
        0x02,
        0xFF,
        f[0],
        f[1],
        f[5],
        f[Msg::ROBUST_LEN - 2],
    ];
    let tails = [
        f.clone(),
        [&f[..], &f].concat(),
        [&f[..1], &f].concat(),
        [&f[..20], &f].concat(),
        [&f[..Msg::ROBUST_LEN - 1], &f].concat(),
    ];
    let mut streams = 0u32;
    for len in 0..=5u32 {
        for code in 0..alphabet.len().pow(len) {
            let mut prefix = std::vec::Vec::new();
            let mut c = code;
            for _ in 0..len {
                prefix.push(alphabet[c % alphabet.len()]);
                c /= alphabet.len();
            }
            for tail in &tails {
                let stream = [prefix.as_slice(), tail].concat();
                let mut dec = RobustDecoder::<4>::new();
                let mut last = None;
                for end in 1..=stream.len() {
                    let got = dec.push(stream[end - 1]);
                    super::verification::check_against_reference(&stream[..end], got);
                    last = got;
                }
                assert_eq!(last, Some(Ok(sample())), "{prefix:02X?} {tail:02X?}");
                streams += 1;
            }
        }
    }
    assert_eq!(streams, 37_449 * 5);
}

/// What a receiver of the legacy packets that splits the stream after each `'\n'` sees.
fn split_lines(stream: &[u8]) -> std::vec::Vec<&[u8]> {
    stream.split_inclusive(|&b| b == DELIMITER).collect()
}

#[test]
fn legacy_split_on_newline_loses_and_corrupts_commands() {
    // Loss: motor 0 to 10 degrees puts 0x0A at offset 8. Split there, the packet is a 9-byte and a
    // 28-byte piece, both refused: the command never arrives, however often it is sent.
    let a = Msg {
        cmd_type: CmdType::Mtrs,
        is_relative: 0,
        mtr_angles: [10, 0, 0, 0],
        mtr_speed_deg_s: 30,
        mtr_accel_deg_s_s: 60,
        cmd_success: 0,
    };
    let mut pa = [0u8; 37];
    a.encode_legacy(&mut pa).unwrap();
    assert_eq!(pa[..12], [0, 0, 0, 0, 0, 0, 0, 0, 0x0A, 0, 0, 0]);
    let pieces = split_lines(&pa);
    assert_eq!(
        pieces.iter().map(|p| p.len()).collect::<std::vec::Vec<_>>(),
        [9, 28]
    );
    assert!(pieces.iter().all(|p| Msg::decode_legacy(p).is_err()));
    // Corruption: A's '\n' lost on the line (one byte dropped), then B, whose motor 0 angle 2560 is
    // 00 0A 00 00 (0x0A at offset 9). The 37 bytes from A's offset 9 to B's offset 9 end in '\n'
    // and decode as a motor command that neither packet holds: A's speed and acceleration bytes,
    // shifted, become angles of motors 1 and 2 (503,316,480 and 1,006,632,960 degrees).
    let b = Msg {
        mtr_angles: [2560, 0, 0, 0],
        ..a
    };
    let mut pb = [0u8; 37];
    b.encode_legacy(&mut pb).unwrap();
    let stream = [&pa[..36], &pb[..]].concat();
    let pieces = split_lines(&stream);
    assert_eq!(
        pieces.iter().map(|p| p.len()).collect::<std::vec::Vec<_>>(),
        [9, 37, 27]
    );
    let forged = Msg::decode_legacy(pieces[1]).unwrap();
    assert_eq!(forged.cmd_type, CmdType::Mtrs);
    assert_ne!(forged, a);
    assert_ne!(forged, b);
    assert_eq!(forged.mtr_angles, [0, 0x1E00_0000, 0x3C00_0000, 0]);
    // The robust frames of the same commands, the same byte lost: A is refused, B delivered.
    let (fa, fb) = (robust(&a), robust(&b));
    let stream = [&fa[..fa.len() - 1], &fb[..]].concat();
    let mut dec = RobustDecoder::<4>::new();
    let got: std::vec::Vec<_> = stream.iter().filter_map(|&x| dec.push(x)).collect();
    assert_eq!(got, [Ok(b)]);
}

/// The layout of robust frames before version 2, rebuilt here from its description:
/// `COBS(1 | CmdMsg | CRC-16 little-endian over 1 | CmdMsg) | 0x00`, the CRC over the body before COBS.
fn v1_frame<const M: usize>(m: &CmdMsg<M>) -> std::vec::Vec<u8> {
    let mut body = vec![1u8; 1 + msg_len(M)];
    m.encode_raw(&mut body[1..]).unwrap();
    let crc = crc16::checksum(&body);
    body.extend_from_slice(&crc.to_le_bytes());
    let mut frame = vec![0u8; corncobs::max_encoded_len(body.len())];
    let n = corncobs::encode_buf(&body, &mut frame);
    frame.truncate(n);
    frame
}

/// A receiver of the layout before version 2: one 0x00 at the end, COBS undone, the body's length,
/// its CRC, version 1, then the message.
fn v1_decode<const M: usize>(frame: &[u8]) -> Option<CmdMsg<M>> {
    if frame.last() != Some(&0) || frame.iter().filter(|&&b| b == 0).count() != 1 {
        return None;
    }
    let mut body = vec![0u8; frame.len()];
    let n = corncobs::decode_buf(frame, &mut body).ok()?;
    let (covered, crc) = body[..n].split_at_checked(n.checked_sub(2)?)?;
    if n != msg_len(M) + 3 || crc16::checksum(covered) != u16::from_le_bytes([crc[0], crc[1]]) {
        return None;
    }
    match covered.split_first()? {
        (1, msg) => CmdMsg::<M>::decode_raw(msg).ok(),
        _ => None,
    }
}

/// The robust frame of `m` as this crate sends it.
fn frame_of<const M: usize>(m: &CmdMsg<M>) -> std::vec::Vec<u8> {
    let mut f = [0u8; ROBUST_BUF];
    let n = m.encode_robust(&mut f).unwrap();
    assert_eq!(n, CmdMsg::<M>::ROBUST_LEN);
    f[..n].to_vec()
}

/// The bits of `frame` whose flip `decode_robust` accepts (none, if every flip is refused).
fn accepted_flips<const M: usize>(frame: &[u8]) -> std::vec::Vec<usize> {
    (0..frame.len() * 8)
        .filter(|&bit| {
            let mut g = frame.to_vec();
            g[bit / 8] ^= 1 << (bit % 8);
            CmdMsg::<M>::decode_robust(&g).is_ok()
        })
        .collect()
}

/// A one-motor command found by a search over random frames: in the layout before version 2 the
/// flip of bit 2 of byte 17 (a COBS code byte, 0x01 → 0x05) moves the zeros of the body, and the
/// body CRC still matches.
fn code_byte_counterexample() -> CmdMsg<1> {
    CmdMsg {
        cmd_type: CmdType::Mtrs,
        is_relative: -63191,
        mtr_angles: [0],
        mtr_speed_deg_s: 32,
        mtr_accel_deg_s_s: 0,
        cmd_success: 4,
    }
}

#[test]
fn a_code_byte_flip_the_body_crc_missed_is_refused() {
    let m = code_byte_counterexample();
    let old = v1_frame(&m);
    let want: std::vec::Vec<u8> = [
        0x02, 0x01, 0x01, 0x01, 0x01, 0x05, 0x29, 0x09, 0xff, 0xff, 0x01, 0x01, 0x01, 0x02, 0x20,
        0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x02, 0x04, 0x01, 0x01, 0x03, 0x02, 0x32, 0x00,
    ]
    .to_vec();
    assert_eq!(old, want);
    assert_eq!(v1_decode::<1>(&old), Some(m));
    // Under the old layout the flip decodes, to a command nobody sent.
    let mut flipped = old.clone();
    flipped[17] ^= 1 << 2;
    assert_eq!(flipped[17], 0x05);
    assert_eq!(
        v1_decode::<1>(&flipped),
        Some(CmdMsg {
            mtr_accel_deg_s_s: 0x0201_0101,
            cmd_success: 0x0301_0100,
            ..m
        })
    );
    // The same command in version 2 (the example of the module documentation, computed outside this
    // crate from the layout): S = COBS(02 | CmdMsg), CRC 0xCECE over S, check bytes 83 9D CE.
    let v2: std::vec::Vec<u8> = [
        0x02, 0x02, 0x01, 0x01, 0x01, 0x05, 0x29, 0x09, 0xff, 0xff, 0x01, 0x01, 0x01, 0x02, 0x20,
        0x01, 0x01, 0x01, 0x01, 0x01, 0x01, 0x02, 0x04, 0x01, 0x01, 0x01, 0x83, 0x9d, 0xce, 0x00,
    ]
    .to_vec();
    assert_eq!(frame_of(&m), v2);
    assert_eq!(accepted_flips::<1>(&v2), [0usize; 0]);
    assert_eq!(
        CmdMsg::<1>::decode_robust(&flipped).map(|_| ()),
        Err(RejectReason::Framing)
    );
}

/// Commands like the search's: small field values, so many zero bytes for COBS to replace.
fn zero_rich<const M: usize>(x: &mut u64) -> CmdMsg<M> {
    let mut next = || {
        *x ^= *x << 13;
        *x ^= *x >> 7;
        *x ^= *x << 17;
        let v = (*x >> 32) as i32;
        match *x % 4 {
            0 => 0,
            1 => v & 0xFF,
            2 => v >> 16,
            _ => v,
        }
    };
    CmdMsg {
        cmd_type: CmdType::from_raw(next().rem_euclid(5)).unwrap(),
        is_relative: next(),
        mtr_angles: core::array::from_fn(|_| next()),
        mtr_speed_deg_s: next(),
        mtr_accel_deg_s_s: next(),
        cmd_success: next(),
    }
}

#[test]
fn every_single_bit_flip_of_zero_rich_frames_is_refused() {
    let mut x = 0x7E_0D0D_u64;
    for _ in 0..300 {
        let m = zero_rich::<1>(&mut x);
        assert_eq!(accepted_flips::<1>(&frame_of(&m)), [0usize; 0], "{m:?}");
        let m = zero_rich::<4>(&mut x);
        assert_eq!(accepted_flips::<4>(&frame_of(&m)), [0usize; 0], "{m:?}");
    }
}

/// Every bit of sample frames of 1, 4 and 16 motors, flipped one at a time: each flip is refused.
#[test]
fn every_bit_of_sample_frames_flipped_is_refused() {
    let mut x = 0x7E_0E0E_u64;
    assert_eq!(
        accepted_flips::<1>(&frame_of(&code_byte_counterexample())),
        [0usize; 0]
    );
    assert_eq!(accepted_flips::<4>(&frame_of(&sample())), [0usize; 0]);
    assert_eq!(
        accepted_flips::<16>(&frame_of(&zero_rich::<16>(&mut x))),
        [0usize; 0]
    );
    assert_eq!(
        accepted_flips::<16>(&frame_of(&CmdMsg::<16>::default())),
        [0usize; 0]
    );
}

/// Every burst of 1 to 16 bits confined to the stuffed bytes `S` (transmission order, most
/// significant bit of each byte first, as the CRC reads them) changes the CRC over `S`, for every
/// motor count (`S` of 26 to 86 bytes): with the check bytes untouched, every such error is refused.
///
/// The CRC is affine (the premise `tables_are_linear` in `crc16`), so the change a pattern makes is
/// the XOR of the changes of its single bits, whatever the frame: each start bit's 2¹⁵ bursts are
/// walked in Gray-code order, one column XORed per step. Spot checks against the CRC itself
/// confirm the columns.
#[test]
fn every_burst_within_the_stuffed_bytes_changes_the_crc() {
    let mut x = 0x7E_0F0F_u64;
    let mut next = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    for m in 1..=MAX_MOTORS {
        let len = stuffed_len(m);
        let bits = len * 8;
        let zeros = vec![0u8; len];
        let base = crc16::checksum(&zeros);
        let columns: std::vec::Vec<u16> = (0..bits)
            .map(|i| {
                let mut e = zeros.clone();
                e[i / 8] ^= 0x80 >> (i % 8);
                crc16::checksum(&e) ^ base
            })
            .collect();
        for start in 0..bits {
            let span = (bits - start).min(16);
            let mut change = columns[start];
            assert_ne!(change, 0, "{m} motors, bit {start}");
            for g in 1u32..(1 << (span - 1)) {
                // Gray code: step g toggles bit `trailing_zeros(g)` of the 15 after `start`.
                change ^= columns[start + 1 + g.trailing_zeros() as usize];
                assert_ne!(change, 0, "{m} motors, burst at {start}, step {g}");
            }
        }
        // The columns predict what the CRC does to real bytes: random S, random bursts.
        for _ in 0..200 {
            let s: std::vec::Vec<u8> = (0..len).map(|_| next() as u8).collect();
            let start = next() as usize % bits;
            let pattern = (next() as u32 | 1) & 0xFFFF;
            let mut t = s.clone();
            let mut predicted = 0u16;
            for i in 0..16 {
                if pattern >> i & 1 == 1 && start + i < bits {
                    t[(start + i) / 8] ^= 0x80 >> ((start + i) % 8);
                    predicted ^= columns[start + i];
                }
            }
            assert_eq!(crc16::checksum(&s) ^ crc16::checksum(&t), predicted);
        }
    }
}

/// `unstuff` writes a block's body only into room for all of it, and only for a block of fewer
/// than 254 data bytes (one code byte cannot say more; 254 would need the 0xFF code). The robust
/// decoder always passes a buffer of the largest body and a block of a fixed length, so these are
/// the function's own limits, checked here by hand-built blocks.
#[test]
fn unstuff_needs_room_for_the_body_and_fewer_than_254_data_bytes() {
    // Body 11 00 22: the code 02 points at the zero (block byte 2), which holds 02, the distance
    // to one past the block's end (4).
    let block = [0x02, 0x11, 0x02, 0x22];
    let mut out = [0xEE; 3];
    assert_eq!(unstuff(&block, &mut out), Some(3));
    assert_eq!(out, [0x11, 0x00, 0x22]);
    assert_eq!(unstuff(&block, &mut [0xEE; 2]), None);
    // 254 data bytes without a zero, code 0xFF: a chain that ends one past the block, but too long.
    let mut long = [0x01; 255];
    long[0] = 0xFF;
    assert_eq!(unstuff(&long, &mut [0xEE; 254]), None);
    // One data byte fewer, code 0xFE: the longest block accepted.
    let mut longest = [0x01; 254];
    longest[0] = 0xFE;
    let mut out = [0xEE; 253];
    assert_eq!(unstuff(&longest, &mut out), Some(253));
    assert!(out.iter().all(|&b| b == 0x01));
}
