//! The serial link between the housing processor and a host: message types
//! shared by both sides, framing, and a streaming decoder.
//!
//! Wire format of one frame (the device side of the paper's system: the
//! 5 fps strobe timing of Section V and the fish of Section IV.D reported to
//! the deck):
//!
//! ```text
//! 0x00 │ COBS( version:u8 │ postcard(message) │ CRC-32(version ‖ message):u32 LE ) │ 0x00
//! ```
//!
//! - COBS removes every 0x00 from the payload, so 0x00 only ever delimits
//!   frames. Frames also *start* with a delimiter, so bytes of garbage before
//!   a frame are cut off instead of spoiling it.
//! - CRC-32 is the ISO-HDLC (zlib, Ethernet) polynomial; the check value of
//!   `b"123456789"` is `0xCBF43926`.
//! - The version byte is checked after the CRC and before the message is
//!   parsed, so an old host meets "protocol version 2, expected 1", not a
//!   parse error.
//!
//! [`Decoder`] takes bytes one at a time into a buffer of [`MAX_ENCODED`]
//! bytes: garbage, truncated or oversized frames, bad CRC and unknown
//! versions come out as [`LinkError`]s and decoding resumes at the next
//! 0x00. Nothing here allocates or panics.

use core::fmt;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use crate::strobe::StrobeConfig;

/// Version of this protocol; bumped on every incompatible message change.
pub const PROTOCOL_VERSION: u8 = 1;
/// Largest postcard-encoded message, bytes.
pub const MAX_MESSAGE: usize = 120;
/// Largest payload: version byte, message, CRC-32.
pub const MAX_PAYLOAD: usize = 1 + MAX_MESSAGE + 4;
/// Largest COBS-encoded payload (without delimiters).
pub const MAX_ENCODED: usize = MAX_PAYLOAD + MAX_PAYLOAD / 254 + 1;
/// Largest frame on the wire, both delimiters included.
pub const MAX_FRAME: usize = MAX_ENCODED + 2;
/// Capacity of [`DeviceError::detail`].
pub const DETAIL_LEN: usize = 48;

const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// A command from the host.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Replace the camera/strobe timing (answered by [`Report::Status`] or
    /// [`Report::Error`]).
    Configure(StrobeConfig),
    /// Free-run the cameras until [`Command::Stop`].
    Start,
    /// Stop triggering.
    Stop,
    /// Ask for [`Report::Status`].
    Status,
    /// Ask for [`Report::Counters`].
    Counters,
    /// Trigger exactly `frames` frames, reporting the edges of each, then
    /// [`Report::BenchDone`].
    RunBench {
        /// Number of frames.
        frames: u32,
    },
}

/// A report from the device.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Report {
    /// State and configuration.
    Status(Status),
    /// Measured edge times of one frame.
    Edges(FrameEdges),
    /// One stereo frame went through the pipeline.
    Frame(FrameReport),
    /// A fish track ended (Section IV.C) with its length (Section IV.D).
    FishClosed(FishClosed),
    /// A bench sequence finished.
    BenchDone {
        /// Frames triggered.
        frames: u32,
    },
    /// Device counters.
    Counters(Counters),
    /// Something went wrong on the device.
    Error(DeviceError),
}

/// Device state.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Free-running or running a bench sequence.
    pub running: bool,
    /// Active timing.
    pub config: StrobeConfig,
    /// Frames triggered since power-up.
    pub frames: u32,
    /// Monotonic clock, µs.
    pub uptime_us: u64,
}

/// Edge times of one frame as the device's pins saw them, µs of the
/// device's monotonic clock; `None` when an edge did not happen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameEdges {
    /// Frame index.
    pub frame: u32,
    /// Left trigger rising edge (exposure of the left camera starts).
    pub trigger_left_rise: Option<u64>,
    /// Left trigger falling edge.
    pub trigger_left_fall: Option<u64>,
    /// Right trigger rising edge.
    pub trigger_right_rise: Option<u64>,
    /// Right trigger falling edge.
    pub trigger_right_fall: Option<u64>,
    /// Strobe on.
    pub strobe_rise: Option<u64>,
    /// Strobe off.
    pub strobe_fall: Option<u64>,
}

/// One frame processed by the pipeline.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FrameReport {
    /// Frame index.
    pub frame: u32,
    /// Segmented objects in the left image (Section III).
    pub objects: u16,
    /// Live tracks after data association (Section IV.C).
    pub tracks: u16,
}

/// A fish whose track ended.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FishClosed {
    /// Track id.
    pub track_id: u32,
    /// First frame of the track.
    pub first_frame: u32,
    /// Last frame of the track.
    pub last_frame: u32,
    /// Length, mm (Section IV.D).
    pub length_mm: f32,
}

/// Device counters since power-up.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Counters {
    /// Frames triggered.
    pub frames: u32,
    /// Edges driven.
    pub edges: u32,
    /// Edges driven after their deadline.
    pub late_edges: u32,
    /// Frames through the pipeline.
    pub frames_processed: u32,
    /// Commands received intact.
    pub rx_frames: u32,
    /// Received frames discarded (garbage, CRC, version).
    pub rx_errors: u32,
    /// Reports sent.
    pub tx_frames: u32,
}

/// What kind of device error.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorCode {
    /// A [`Command::Configure`] failed validation.
    BadConfig,
    /// A received frame was discarded.
    BadFrame,
    /// The command is not allowed while running.
    Busy,
    /// A pin failed.
    Pin,
    /// The frame source failed.
    FrameSource,
}

/// A device error with a short text.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DeviceError {
    /// Kind.
    pub code: ErrorCode,
    /// Human-readable detail, truncated to [`DETAIL_LEN`] bytes.
    pub detail: heapless::String<DETAIL_LEN>,
}

impl DeviceError {
    /// An error whose detail is the first [`DETAIL_LEN`] bytes (at a char
    /// boundary) of `text`.
    pub fn new(code: ErrorCode, text: &str) -> Self {
        let mut detail = heapless::String::new();
        for c in text.chars() {
            if detail.push(c).is_err() {
                break;
            }
        }
        DeviceError { code, detail }
    }
}

/// Why a frame could not be encoded or decoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum LinkError {
    /// The frame ended before its COBS blocks, or is shorter than a version
    /// byte and a CRC.
    Truncated,
    /// More than [`MAX_ENCODED`] bytes between delimiters.
    Oversized,
    /// The CRC-32 does not match.
    BadCrc {
        /// CRC carried by the frame.
        received: u32,
        /// CRC computed over the payload.
        computed: u32,
    },
    /// The frame is from another protocol version.
    Version {
        /// Version byte of the frame.
        got: u8,
        /// [`PROTOCOL_VERSION`].
        expected: u8,
    },
    /// The CRC matched but the message does not parse (or has trailing bytes).
    Malformed,
    /// The message needs more than [`MAX_MESSAGE`] bytes.
    MessageTooLarge,
    /// The output buffer is smaller than the frame.
    BufferTooSmall,
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkError::Truncated => write!(f, "truncated frame"),
            LinkError::Oversized => write!(f, "oversized frame (over {MAX_ENCODED} bytes)"),
            LinkError::BadCrc { received, computed } => {
                write!(f, "bad CRC-32 {received:#010x}, computed {computed:#010x}")
            }
            LinkError::Version { got, expected } => {
                write!(f, "protocol version {got}, expected {expected}")
            }
            LinkError::Malformed => write!(f, "malformed message"),
            LinkError::MessageTooLarge => write!(f, "message over {MAX_MESSAGE} bytes"),
            LinkError::BufferTooSmall => write!(f, "output buffer too small"),
        }
    }
}

impl core::error::Error for LinkError {}

/// CRC-32 (ISO-HDLC) of `bytes`.
pub fn crc32(bytes: &[u8]) -> u32 {
    CRC.checksum(bytes)
}

/// Encode `msg` as one frame (both delimiters included) into `out`;
/// returns the frame length. `out` of [`MAX_FRAME`] bytes always suffices.
pub fn encode<M: Serialize>(msg: &M, out: &mut [u8]) -> Result<usize, LinkError> {
    encode_with_version(PROTOCOL_VERSION, msg, out)
}

/// [`encode`] with another version byte (tests and fault injection).
pub fn encode_with_version<M: Serialize>(
    version: u8,
    msg: &M,
    out: &mut [u8],
) -> Result<usize, LinkError> {
    let mut payload = [0u8; MAX_PAYLOAD];
    let (head, rest) = payload.split_at_mut(1);
    if let Some(v) = head.first_mut() {
        *v = version;
    }
    let body = rest
        .get_mut(..MAX_MESSAGE)
        .ok_or(LinkError::MessageTooLarge)?;
    let n = postcard::to_slice(msg, body)
        .map_err(|_| LinkError::MessageTooLarge)?
        .len();
    let crc_at = 1 + n;
    let crc = crc32(payload.get(..crc_at).ok_or(LinkError::MessageTooLarge)?);
    payload
        .get_mut(crc_at..crc_at + 4)
        .ok_or(LinkError::MessageTooLarge)?
        .copy_from_slice(&crc.to_le_bytes());
    let src = payload
        .get(..crc_at + 4)
        .ok_or(LinkError::MessageTooLarge)?;

    let (first, body) = out.split_first_mut().ok_or(LinkError::BufferTooSmall)?;
    *first = 0;
    let m = cobs_encode(src, body)?;
    *body.get_mut(m).ok_or(LinkError::BufferTooSmall)? = 0;
    Ok(m + 2)
}

/// Decode one COBS-encoded frame (delimiters stripped) into a message.
pub fn decode_frame<M: DeserializeOwned>(encoded: &[u8]) -> Result<M, LinkError> {
    if encoded.len() > MAX_ENCODED {
        return Err(LinkError::Oversized);
    }
    let mut payload = [0u8; MAX_ENCODED];
    let n = cobs_decode(encoded, &mut payload)?;
    let payload = payload.get(..n).ok_or(LinkError::Truncated)?;
    if n < 5 {
        return Err(LinkError::Truncated);
    }
    let (data, crc_bytes) = payload.split_at(n - 4);
    let mut le = [0u8; 4];
    le.copy_from_slice(crc_bytes);
    let received = u32::from_le_bytes(le);
    let computed = crc32(data);
    if received != computed {
        return Err(LinkError::BadCrc { received, computed });
    }
    let (&version, body) = data.split_first().ok_or(LinkError::Truncated)?;
    if version != PROTOCOL_VERSION {
        return Err(LinkError::Version {
            got: version,
            expected: PROTOCOL_VERSION,
        });
    }
    match postcard::take_from_bytes::<M>(body) {
        Ok((msg, [])) => Ok(msg),
        _ => Err(LinkError::Malformed),
    }
}

/// COBS-encode `src` into `dst` (no delimiter); returns the encoded length.
pub fn cobs_encode(src: &[u8], dst: &mut [u8]) -> Result<usize, LinkError> {
    let mut code_at = 0;
    let mut out = 1;
    let mut code: u8 = 1;
    if dst.is_empty() {
        return Err(LinkError::BufferTooSmall);
    }
    for &b in src {
        if b == 0 {
            *dst.get_mut(code_at).ok_or(LinkError::BufferTooSmall)? = code;
            code_at = out;
            out += 1;
            code = 1;
        } else {
            *dst.get_mut(out).ok_or(LinkError::BufferTooSmall)? = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                *dst.get_mut(code_at).ok_or(LinkError::BufferTooSmall)? = code;
                code_at = out;
                out += 1;
                code = 1;
            }
        }
    }
    *dst.get_mut(code_at).ok_or(LinkError::BufferTooSmall)? = code;
    Ok(out)
}

/// COBS-decode `src` (no delimiter) into `dst`; returns the decoded length.
/// A zero byte inside `src`, or a block running past its end, is
/// [`LinkError::Truncated`]; a `dst` too small is [`LinkError::Oversized`].
pub fn cobs_decode(src: &[u8], dst: &mut [u8]) -> Result<usize, LinkError> {
    let mut i = 0;
    let mut out = 0;
    while let Some(&code) = src.get(i) {
        if code == 0 {
            return Err(LinkError::Truncated);
        }
        let start = i + 1;
        let end = i + usize::from(code);
        let block = src.get(start..end).ok_or(LinkError::Truncated)?;
        if block.contains(&0) {
            return Err(LinkError::Truncated);
        }
        dst.get_mut(out..out + block.len())
            .ok_or(LinkError::Oversized)?
            .copy_from_slice(block);
        out += block.len();
        i = end;
        if code != 0xFF && i < src.len() {
            *dst.get_mut(out).ok_or(LinkError::Oversized)? = 0;
            out += 1;
        }
    }
    Ok(out)
}

/// Decoder statistics.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecoderStats {
    /// Frames decoded into messages.
    pub frames: u32,
    /// Frames discarded with an error.
    pub errors: u32,
    /// Bytes of the discarded frames.
    pub discarded_bytes: u32,
}

/// Streaming frame decoder with a bounded buffer of [`MAX_ENCODED`] bytes.
#[derive(Debug, Clone)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Decoder {
    buf: [u8; MAX_ENCODED],
    len: usize,
    overflow: u32,
    stats: DecoderStats,
}

impl Default for Decoder {
    fn default() -> Self {
        Decoder::new()
    }
}

impl Decoder {
    /// An empty decoder.
    pub const fn new() -> Self {
        Decoder {
            buf: [0; MAX_ENCODED],
            len: 0,
            overflow: 0,
            stats: DecoderStats {
                frames: 0,
                errors: 0,
                discarded_bytes: 0,
            },
        }
    }

    /// Counts so far.
    pub const fn stats(&self) -> DecoderStats {
        self.stats
    }

    /// Forget a partly received frame.
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflow = 0;
    }

    /// Feed one byte. At a delimiter that ends a non-empty frame, returns
    /// the frame's message or why it was discarded; otherwise `None`.
    pub fn push<M: DeserializeOwned>(&mut self, byte: u8) -> Option<Result<M, LinkError>> {
        if byte != 0 {
            match self.buf.get_mut(self.len) {
                Some(slot) => {
                    *slot = byte;
                    self.len += 1;
                }
                None => self.overflow = self.overflow.saturating_add(1),
            }
            return None;
        }
        if self.len == 0 && self.overflow == 0 {
            return None;
        }
        let result = if self.overflow > 0 {
            Err(LinkError::Oversized)
        } else {
            decode_frame(self.buf.get(..self.len).unwrap_or(&[]))
        };
        match result {
            Ok(_) => self.stats.frames = self.stats.frames.saturating_add(1),
            Err(_) => {
                let bytes = u32::try_from(self.len).unwrap_or(u32::MAX);
                self.stats.errors = self.stats.errors.saturating_add(1);
                self.stats.discarded_bytes = self
                    .stats
                    .discarded_bytes
                    .saturating_add(bytes)
                    .saturating_add(self.overflow);
            }
        }
        self.reset();
        Some(result)
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::vec::Vec;

    fn frame<M: Serialize>(m: &M) -> Vec<u8> {
        let mut out = [0u8; MAX_FRAME];
        let n = encode(m, &mut out).unwrap();
        out[..n].to_vec()
    }

    fn decode_all<M: DeserializeOwned>(bytes: &[u8]) -> Vec<Result<M, LinkError>> {
        let mut d = Decoder::new();
        bytes.iter().filter_map(|&b| d.push(b)).collect()
    }

    fn edges() -> Report {
        Report::Edges(FrameEdges {
            frame: 7,
            trigger_left_rise: Some(1_400_500),
            trigger_left_fall: Some(1_400_600),
            trigger_right_rise: Some(1_400_501),
            trigger_right_fall: None,
            strobe_rise: Some(1_400_000),
            strobe_fall: Some(u64::MAX),
        })
    }

    #[test]
    fn crc32_known_answer() {
        assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    }

    #[test]
    fn cobs_known_answers() {
        // Examples of Cheshire & Baker (1999) / the COBS Wikipedia page.
        let cases: [(&[u8], &[u8]); 5] = [
            (&[0x00], &[0x01, 0x01]),
            (&[0x00, 0x00], &[0x01, 0x01, 0x01]),
            (&[0x11, 0x22, 0x00, 0x33], &[0x03, 0x11, 0x22, 0x02, 0x33]),
            (&[0x11, 0x22, 0x33, 0x44], &[0x05, 0x11, 0x22, 0x33, 0x44]),
            (&[0x11, 0x00, 0x00, 0x00], &[0x02, 0x11, 0x01, 0x01, 0x01]),
        ];
        for (raw, enc) in cases {
            let mut out = [0u8; 16];
            let n = cobs_encode(raw, &mut out).unwrap();
            assert_eq!(&out[..n], enc);
            let mut back = [0u8; 16];
            let m = cobs_decode(enc, &mut back).unwrap();
            assert_eq!(&back[..m], raw);
        }
        // 254 non-zero bytes: one full block, then an empty one.
        let raw: Vec<u8> = (1..=254).collect();
        let mut out = [0u8; 300];
        let n = cobs_encode(&raw, &mut out).unwrap();
        assert_eq!(n, 256);
        assert_eq!((out[0], out[255]), (0xFF, 0x01));
    }

    #[test]
    fn every_message_round_trips() {
        let msgs = [
            edges(),
            Report::Status(Status {
                running: true,
                config: StrobeConfig::default(),
                frames: 3,
                uptime_us: 600_000,
            }),
            Report::Frame(FrameReport {
                frame: 1,
                objects: 4,
                tracks: 2,
            }),
            Report::FishClosed(FishClosed {
                track_id: 9,
                first_frame: 3,
                last_frame: 12,
                length_mm: 412.5,
            }),
            Report::BenchDone { frames: 25 },
            Report::Counters(Counters {
                frames: u32::MAX,
                rx_errors: 3,
                ..Default::default()
            }),
            Report::Error(DeviceError::new(ErrorCode::BadConfig, &"x".repeat(200))),
        ];
        for m in &msgs {
            let f = frame(m);
            assert!(f.len() <= MAX_FRAME);
            assert_eq!((f[0], f[f.len() - 1]), (0, 0));
            assert_eq!(f[1..f.len() - 1].iter().filter(|&&b| b == 0).count(), 0);
            assert_eq!(decode_all::<Report>(&f), vec![Ok(m.clone())]);
        }
        let cmds = [
            Command::Configure(StrobeConfig::default()),
            Command::Start,
            Command::Stop,
            Command::Status,
            Command::Counters,
            Command::RunBench { frames: 25 },
        ];
        for c in &cmds {
            assert_eq!(decode_all::<Command>(&frame(c)), vec![Ok(*c)]);
        }
        // The detail was cut at its capacity.
        if let Report::Error(e) = &msgs[6] {
            assert_eq!(e.detail.len(), DETAIL_LEN);
        }
    }

    #[test]
    fn largest_message_fits() {
        let worst = Report::Edges(FrameEdges {
            frame: u32::MAX,
            trigger_left_rise: Some(u64::MAX),
            trigger_left_fall: Some(u64::MAX),
            trigger_right_rise: Some(u64::MAX),
            trigger_right_fall: Some(u64::MAX),
            strobe_rise: Some(u64::MAX),
            strobe_fall: Some(u64::MAX),
        });
        let mut buf = [0u8; MAX_MESSAGE];
        assert!(postcard::to_slice(&worst, &mut buf).is_ok());
        let err = Report::Error(DeviceError::new(ErrorCode::FrameSource, &"é".repeat(40)));
        assert!(postcard::to_slice(&err, &mut buf).is_ok());
    }

    #[test]
    fn other_version_is_named() {
        let mut out = [0u8; MAX_FRAME];
        let n = encode_with_version(2, &Command::Status, &mut out).unwrap();
        let got = decode_all::<Command>(&out[..n]);
        assert_eq!(
            got,
            vec![Err(LinkError::Version {
                got: 2,
                expected: 1
            })]
        );
        assert_eq!(
            std::format!("{}", got[0].unwrap_err()),
            "protocol version 2, expected 1"
        );
    }

    #[test]
    fn damaged_frames_are_errors_and_the_next_frame_decodes() {
        let good = frame(&edges());
        // Bit flip inside the payload → bad CRC.
        let mut flipped = good.clone();
        flipped[5] ^= 0x10;
        if flipped[5] == 0 {
            flipped[5] = 0x55;
        }
        let mut stream = flipped.clone();
        stream.extend_from_slice(&good);
        let got = decode_all::<Report>(&stream);
        assert_eq!(got.len(), 2);
        assert!(matches!(
            got[0],
            Err(LinkError::BadCrc { .. }) | Err(LinkError::Truncated)
        ));
        assert_eq!(got[1], Ok(edges()));

        // Truncated: the frame is cut and a delimiter follows.
        let mut cut = good[..good.len() / 2].to_vec();
        cut.push(0);
        cut.extend_from_slice(&good);
        let got = decode_all::<Report>(&cut);
        assert!(got[0].is_err());
        assert_eq!(got.last(), Some(&Ok(edges())));

        // Oversized: 1000 non-zero bytes, then a good frame.
        let mut big = vec![0x41u8; 1000];
        big.extend_from_slice(&good);
        let mut d = Decoder::new();
        let got: Vec<Result<Report, _>> = big.iter().filter_map(|&b| d.push(b)).collect();
        assert_eq!(got, vec![Err(LinkError::Oversized), Ok(edges())]);
        assert_eq!(
            d.stats(),
            DecoderStats {
                frames: 1,
                errors: 1,
                discarded_bytes: 1000
            }
        );

        // A valid Report frame read as a Command: CRC fine, message not.
        let got = decode_all::<Command>(&frame(&Report::Counters(Counters::default())));
        assert_eq!(got, vec![Err(LinkError::Malformed)]);

        // Too short to hold a version and a CRC.
        assert_eq!(
            decode_frame::<Command>(&[0x03, 0x01, 0x02]),
            Err(LinkError::Truncated)
        );
        assert_eq!(
            decode_frame::<Command>(&[0x09, 0x01]),
            Err(LinkError::Truncated)
        );
    }

    fn report() -> impl Strategy<Value = Report> {
        let opt = proptest::option::of(any::<u64>());
        prop_oneof![
            (
                any::<u32>(),
                opt.clone(),
                opt.clone(),
                opt.clone(),
                opt.clone(),
                opt.clone(),
                opt
            )
                .prop_map(|(frame, a, b, c, d, e, f)| Report::Edges(FrameEdges {
                    frame,
                    trigger_left_rise: a,
                    trigger_left_fall: b,
                    trigger_right_rise: c,
                    trigger_right_fall: d,
                    strobe_rise: e,
                    strobe_fall: f,
                })),
            (any::<u32>(), any::<u16>(), any::<u16>()).prop_map(|(frame, objects, tracks)| {
                Report::Frame(FrameReport {
                    frame,
                    objects,
                    tracks,
                })
            }),
            (any::<u32>(), any::<u32>(), any::<u32>(), 0f32..5000.0).prop_map(
                |(track_id, first_frame, last_frame, length_mm)| {
                    Report::FishClosed(FishClosed {
                        track_id,
                        first_frame,
                        last_frame,
                        length_mm,
                    })
                }
            ),
            "[ -~]{0,60}".prop_map(|s| Report::Error(DeviceError::new(ErrorCode::BadFrame, &s))),
            any::<u32>().prop_map(|frames| Report::BenchDone { frames }),
        ]
    }

    proptest! {
        // Miri interprets every step: a handful of cases checks the unsafe code paths in dependencies.
        #![proptest_config(ProptestConfig::with_cases(if cfg!(miri) { 4 } else { 512 }))]

        /// Random bytes: no panic, and every frame is an error (a CRC-32
        /// collision aside, which 512 cases will not meet).
        #[test]
        fn random_bytes_never_panic(bytes in proptest::collection::vec(any::<u8>(), 0..2000)) {
            let mut d = Decoder::new();
            for &b in &bytes {
                let _ = d.push::<Report>(b);
            }
            let _ = decode_frame::<Command>(&bytes);
            let mut out = [0u8; 64];
            let _ = cobs_decode(&bytes, &mut out);
        }

        /// Valid frames embedded among garbage are all decoded, in order.
        #[test]
        fn valid_frames_among_garbage_are_all_decoded(
            parts in proptest::collection::vec(
                (proptest::collection::vec(any::<u8>(), 0..300), report()), 1..12),
            tail in proptest::collection::vec(any::<u8>(), 0..300),
        ) {
            let mut stream = Vec::new();
            for (garbage, msg) in &parts {
                stream.extend_from_slice(garbage);
                stream.extend_from_slice(&frame(msg));
            }
            stream.extend_from_slice(&tail);
            let got: Vec<Report> = decode_all::<Report>(&stream).into_iter().filter_map(Result::ok).collect();
            let want: Vec<Report> = parts.into_iter().map(|p| p.1).collect();
            prop_assert_eq!(got, want);
        }

        /// COBS round trip on arbitrary payloads.
        #[test]
        fn cobs_round_trips(raw in proptest::collection::vec(any::<u8>(), 0..600)) {
            let mut enc = vec![0u8; raw.len() + raw.len() / 254 + 1];
            let n = cobs_encode(&raw, &mut enc).unwrap();
            prop_assert!(!enc[..n].contains(&0));
            let mut dec = vec![0u8; raw.len()];
            let m = cobs_decode(&enc[..n], &mut dec).unwrap();
            prop_assert_eq!(&dec[..m], &raw[..]);
        }
    }
}
