//! The serial link's streaming decoder on random bytes: it must never
//! panic, and every message it decodes must re-encode into a frame that
//! decodes to an equal message. The first byte picks the direction
//! (even: host-to-device `Command`, odd: device-to-host `Report`).
#![no_main]

use fishtrack_core::link::{decode_frame, encode, Command, Decoder, LinkError, Report, MAX_FRAME};
use libfuzzer_sys::fuzz_target;
use serde::{de::DeserializeOwned, Serialize};

fn check<M>(bytes: &[u8])
where
    M: DeserializeOwned + Serialize + PartialEq + core::fmt::Debug,
{
    let mut d = Decoder::new();
    let mut ok = 0u32;
    let mut err = 0u32;
    for &byte in bytes {
        match d.push::<M>(byte) {
            None => {}
            Some(Err(_)) => err += 1,
            Some(Ok(msg)) => {
                ok += 1;
                let mut out = [0u8; MAX_FRAME];
                let n = encode(&msg, &mut out).expect("a decoded message re-encodes");
                assert!(n <= MAX_FRAME);
                assert_eq!(out[0], 0);
                assert_eq!(out[n - 1], 0);
                let inner = &out[1..n - 1];
                assert!(!inner.contains(&0), "COBS output holds a zero");
                let again: Result<M, LinkError> = decode_frame(inner);
                assert_eq!(again.as_ref().ok(), Some(&msg), "round trip: {again:?}");
                // And through a fresh streaming decoder.
                let mut d2 = Decoder::new();
                let got: Vec<_> = out[..n].iter().filter_map(|&b| d2.push::<M>(b)).collect();
                assert_eq!(got.len(), 1);
                assert_eq!(got[0].as_ref().ok(), Some(&msg));
            }
        }
    }
    let s = d.stats();
    assert_eq!((s.frames, s.errors), (ok, err));
}

fuzz_target!(|data: &[u8]| {
    let Some((&dir, bytes)) = data.split_first() else {
        return;
    };
    if dir & 1 == 0 {
        check::<Command>(bytes);
    } else {
        check::<Report>(bytes);
    }
});
