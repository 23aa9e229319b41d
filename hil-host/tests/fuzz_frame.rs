//! Fuzzing the lockstep frame decoder (`model_core::ecu::frame`) on stable Rust: arbitrary
//! bytes into `decode` and into the streaming `FrameDecoder`, and structured mutations of
//! valid frames (every byte corrupted, cut, extended, length byte changed, frames glued
//! together with junk). It must never panic, answer within [`fuzz_common::HANG_LIMIT`], never accept a
//! frame with a corrupted byte (the CRC-16 catches every error burst within one byte), and
//! re-encode what it accepts to the bytes it came from.
//!
//! Valid frames are made from the wire format alone (sync, version, kind, length, payload,
//! CRC over version..payload) with random payloads, the payload lengths found by asking the
//! decoder, so the harness does not depend on the frames' fields.
//!
//! Long run: `FUZZ_CASES=1000000 cargo test -p hil-host --test fuzz_frame -- --ignored --nocapture`.

mod fuzz_common;

use fuzz_common::{cases, fuzz};

use model_core::ecu::frame::{
    crc16, decode, encode, FrameDecoder, FrameError, FRAME_VERSION, MAX_FRAME_BYTES, MAX_PAYLOAD_BYTES, SYNC,
};
use proptest::prelude::*;
use proptest::test_runner::TestCaseError;

/// A frame on the wire around `payload`.
fn wire(kind: u8, payload: &[u8]) -> Vec<u8> {
    let mut b = SYNC.to_vec();
    b.extend([FRAME_VERSION, kind, payload.len() as u8]);
    b.extend_from_slice(payload);
    let crc = crc16(&b[2..]);
    b.extend(crc.to_le_bytes());
    b
}

/// (kind, payload length) pairs the decoder takes: those where a zero payload fails for
/// another reason than its length.
fn kinds() -> Vec<(u8, usize)> {
    let mut found = Vec::new();
    for kind in 0..=255u8 {
        for len in 0..=MAX_PAYLOAD_BYTES {
            let r = decode(&wire(kind, &vec![0; len]));
            if !matches!(
                r,
                Err(FrameError::BadLength | FrameError::BadKind | FrameError::BadVersion)
            ) {
                found.push((kind, len));
            }
        }
    }
    assert!(found.len() >= 3, "frame kinds found: {found:?}");
    found
}

/// Decodes and, when accepted, checks the frame re-encodes to the same bytes.
fn decode_checked(bytes: &[u8]) -> Result<bool, TestCaseError> {
    match decode(bytes) {
        Err(_) => Ok(false),
        Ok(frame) => {
            let mut buf = [0u8; MAX_FRAME_BYTES];
            let n = encode(&frame, &mut buf).map_err(|e| TestCaseError::fail(format!("re-encode: {e:?}")))?;
            prop_assert_eq!(&buf[..n], bytes, "accepted bytes do not re-encode to themselves");
            Ok(true)
        }
    }
}

/// Streams bytes through the decoder; every frame it returns must decode alone.
fn stream(bytes: &[u8]) -> Result<bool, TestCaseError> {
    let mut dec = FrameDecoder::new();
    let (mut results, mut frames) = (0usize, 0usize);
    for &b in bytes {
        let mut r = dec.push(b);
        while let Some(x) = r {
            results += 1;
            if let Ok(f) = x {
                frames += 1;
                let mut buf = [0u8; MAX_FRAME_BYTES];
                let n = encode(&f, &mut buf).map_err(|e| TestCaseError::fail(format!("{e:?}")))?;
                prop_assert_eq!(decode(&buf[..n]), Ok(f));
            }
            r = dec.poll();
        }
        prop_assert!(dec.pending() <= MAX_FRAME_BYTES);
    }
    prop_assert!(results <= bytes.len());
    Ok(frames > 0)
}

fn valid_frames() -> impl Strategy<Value = Vec<u8>> {
    let kinds = kinds();
    (
        0..kinds.len(),
        proptest::collection::vec(any::<u8>(), MAX_PAYLOAD_BYTES..=MAX_PAYLOAD_BYTES),
    )
        .prop_map(move |(k, payload)| {
            let (kind, len) = kinds[k];
            wire(kind, &payload[..len])
        })
}

fn all_targets(n: u32) {
    fuzz(
        "frame/bytes",
        proptest::collection::vec(any::<u8>(), 0..2 * MAX_FRAME_BYTES),
        n,
        |b| decode_checked(b),
    );
    fuzz("frame/stream", proptest::collection::vec(any::<u8>(), 0..600), n, |b| {
        stream(b)
    });
    // One corrupted byte anywhere in a frame (valid or not): never accepted if it was valid.
    fuzz(
        "frame/corrupted",
        (valid_frames(), any::<usize>(), 1u8..=255),
        n,
        |(f, at, x)| {
            let valid = decode(f).is_ok();
            let mut b = f.clone();
            let i = at % b.len();
            b[i] ^= x;
            let ok = decode_checked(&b)?;
            prop_assert!(
                !(valid && ok),
                "a frame with byte {} corrupted (xor {:#04x}) was accepted",
                i,
                x
            );
            Ok(valid)
        },
    );
    // Cut, extended, or the length byte changed.
    fuzz(
        "frame/reshaped",
        (valid_frames(), any::<usize>(), any::<u8>(), 0u8..3),
        n,
        |(f, at, x, how)| {
            let mut b = f.clone();
            match how {
                0 => b.truncate(at % b.len()),
                1 => b.extend(std::iter::repeat_n(*x, at % 8 + 1)),
                _ => b[4] = *x,
            }
            let ok = decode_checked(&b)?;
            prop_assert!(!(ok && b != *f && b.len() == f.len() && decode(f).is_ok()));
            Ok(ok)
        },
    );
    // Valid frames between junk, streamed: no panic, and no more frames come out than went in.
    fuzz(
        "frame/stream-mixed",
        proptest::collection::vec((valid_frames(), proptest::collection::vec(any::<u8>(), 0..12)), 1..5),
        n,
        |parts| {
            let mut bytes = Vec::new();
            let mut valid = 0;
            for (f, junk) in parts {
                bytes.extend(junk);
                bytes.extend(f);
                valid += usize::from(decode(f).is_ok());
            }
            stream(&bytes)?;
            // Junk may hide a frame (a junk sync plus a length that swallows it), never add one.
            let mut dec = FrameDecoder::new();
            let mut got = 0;
            for &b in &bytes {
                let mut r = dec.push(b);
                while let Some(x) = r {
                    got += usize::from(x.is_ok());
                    r = dec.poll();
                }
            }
            prop_assert!(got <= valid + 1, "{} frames from {} valid", got, valid);
            Ok(got > 0)
        },
    );
}

#[test]
fn frame_fuzz_short() {
    all_targets(cases(2000));
}

#[test]
#[ignore = "long run (>= 10^6 inputs per target), figures in docs/reliability.md"]
fn frame_fuzz_long() {
    all_targets(cases(1_000_000));
}
