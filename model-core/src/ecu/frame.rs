//! The lockstep link between a HIL host and the ECU (processor in the loop): each step the
//! host sends a [`SensorFrame`] (what the ECU's inputs see) and the ECU answers an
//! [`ActuatorFrame`] (what its outputs drive), or a [`Nack`] for a frame it could not trust.
//!
//! Wire format (all multi-byte fields little endian, f32 as its IEEE-754 bits, so values cross
//! the link bit-exactly):
//!
//! ```text
//! 0x55 0xEC | version u8 | kind u8 | payload_len u8 | payload | CRC-16 (LE)
//! ```
//!
//! The CRC is CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF) over version..payload: it
//! catches every burst up to 16 bits, which covers the single corrupted bytes of a UART with
//! a noisy line. Decoding checks, in order, the length bound, the CRC, the version, the kind,
//! the payload length for that kind and every field (flags, enum codes, finite floats): a
//! frame that fails any check is reported and never used.

use super::board::{Edge, EdgeSource, SolenoidCmd};
use super::ehvva_task::ValveRequest;
use super::supervisor::N_CHANNELS;

/// Bumped whenever a payload layout changes; a peer with another version is rejected.
pub const FRAME_VERSION: u8 = 1;
pub const SYNC: [u8; 2] = [0x55, 0xEC];
/// Edges one sensor frame can carry (a 60-2 wheel at 7000 rpm gives < 1 tooth per 50 µs).
pub const MAX_EDGES: usize = 8;
/// sync (2) + version + kind + length.
const HEADER_BYTES: usize = 5;
const CRC_BYTES: usize = 2;
/// The largest payload (a sensor frame with [`MAX_EDGES`] edges).
pub const MAX_PAYLOAD_BYTES: usize = SENSOR_FIXED_BYTES + 5 * MAX_EDGES;
pub const MAX_FRAME_BYTES: usize = HEADER_BYTES + MAX_PAYLOAD_BYTES + CRC_BYTES;

const SENSOR_FIXED_BYTES: usize = 4 + 4 + 1 + 2 * N_CHANNELS + 9 + 4 + 12 + 1;
const ACTUATOR_BYTES: usize = 4 + 4 + 5 + 1 + 4 + 12 + 4 + 4;
const NACK_BYTES: usize = 4 + 4 + 1;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum FrameKind {
    Sensor = 1,
    Actuator = 2,
    Nack = 3,
}

/// Why a frame was rejected.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[repr(u8)]
pub enum FrameError {
    /// The peer speaks another [`FRAME_VERSION`].
    BadVersion = 1,
    BadKind = 2,
    /// Payload length above [`MAX_PAYLOAD_BYTES`] or wrong for the kind.
    BadLength = 3,
    BadCrc = 4,
    /// A field out of its domain: unknown flag bits or enum code, non-finite float, too many
    /// edges.
    BadPayload = 5,
    /// The encoder's output buffer is too small (a programming error, never from the wire).
    BufferTooSmall = 6,
}

impl FrameError {
    pub fn from_code(code: u8) -> Option<Self> {
        Some(match code {
            1 => Self::BadVersion,
            2 => Self::BadKind,
            3 => Self::BadLength,
            4 => Self::BadCrc,
            5 => Self::BadPayload,
            6 => Self::BufferTooSmall,
            _ => return None,
        })
    }
}

/// What the ECU's inputs see during one lockstep step ending at `t_us`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SensorFrame {
    /// Step number; a repeated `seq` is a retransmission (answered, not stepped again).
    pub seq: u32,
    /// The ECU's clock at the end of this step (µs, wrapping).
    pub t_us: u32,
    /// Captured crank/cam edges since the previous frame, in time order; `edges[..n_edges]`.
    pub n_edges: u8,
    pub edges: [Edge; MAX_EDGES],
    /// Raw 12-bit ADC counts in [`super::supervisor::Channel`] order (sensor faults are made
    /// here: 0 = open wire, 4095 = short to supply).
    pub adc_counts: [u16; N_CHANNELS],
    /// Setpoints from the engine management (over CAN on a car).
    pub valve: ValveRequest,
    pub cam_phase_set_deg: f32,
    /// LPT, HPT, HPC position setpoints.
    pub vacuum_x_set_pct: [f32; 3],
    /// The EVVT motor driver's fault pin.
    pub motor_driver_fault: bool,
}

impl SensorFrame {
    pub const NO_EDGE: Edge = Edge {
        source: EdgeSource::CrankTooth,
        t_us: 0,
    };

    /// The valid edges.
    pub fn edges(&self) -> &[Edge] {
        let n = (self.n_edges as usize).min(MAX_EDGES);
        &self.edges[..n]
    }
}

/// What the ECU's outputs drive after the step.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ActuatorFrame {
    /// The `seq` of the sensor frame this answers.
    pub seq: u32,
    pub t_us: u32,
    pub pilot: SolenoidCmd,
    pub lift_valve_on: bool,
    pub snubber_on: bool,
    /// EVVT motor speed command output, 0..1.
    pub motor_duty: f32,
    /// Vacuum valve PWM duties 0..1, LPT, HPT, HPC.
    pub vacuum_duty: [f32; 3],
    pub pump_on: bool,
    /// The supervisor's active faults ([`super::supervisor::FaultSet`] bits).
    pub faults: u32,
    /// Frames the ECU rejected so far (filled in by the link, not by the control code).
    pub bad_frames: u32,
}

/// The answer to a frame that failed a check.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Nack {
    /// The `seq` the ECU expects next (one after the last one it stepped).
    pub seq_expected: u32,
    pub bad_frames: u32,
    /// A [`FrameError`] code.
    pub reason: u8,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Frame {
    Sensor(SensorFrame),
    Actuator(ActuatorFrame),
    Nack(Nack),
}

/// CRC-16/CCITT-FALSE (check value 0x29B1 for "123456789").
pub fn crc16(bytes: &[u8]) -> u16 {
    let mut crc: u16 = 0xFFFF;
    for &b in bytes {
        crc ^= (b as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 {
                (crc << 1) ^ 0x1021
            } else {
                crc << 1
            };
        }
    }
    crc
}

/// Appends fields to a slice; every write is bounds-checked (an overflow sets `overflow`
/// instead of panicking).
struct Writer<'a> {
    buf: &'a mut [u8],
    at: usize,
    overflow: bool,
}

impl Writer<'_> {
    fn bytes(&mut self, b: &[u8]) {
        match self.buf.get_mut(self.at..self.at + b.len()) {
            Some(dst) => {
                dst.copy_from_slice(b);
                self.at += b.len();
            }
            None => self.overflow = true,
        }
    }
    fn u8(&mut self, v: u8) {
        self.bytes(&[v]);
    }
    fn u16(&mut self, v: u16) {
        self.bytes(&v.to_le_bytes());
    }
    fn u32(&mut self, v: u32) {
        self.bytes(&v.to_le_bytes());
    }
    fn f32(&mut self, v: f32) {
        self.u32(v.to_bits());
    }
}

/// Reads fields from a payload of checked length; a short read or a bad field is an error.
struct Reader<'a> {
    buf: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], FrameError> {
        let mut out = [0u8; N];
        let src = self.buf.get(self.at..self.at + N).ok_or(FrameError::BadLength)?;
        out.copy_from_slice(src);
        self.at += N;
        Ok(out)
    }
    fn u8(&mut self) -> Result<u8, FrameError> {
        Ok(self.take::<1>()?[0])
    }
    fn u16(&mut self) -> Result<u16, FrameError> {
        Ok(u16::from_le_bytes(self.take()?))
    }
    fn u32(&mut self) -> Result<u32, FrameError> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    /// Finite floats only: a NaN duty or setpoint is never passed on.
    fn f32(&mut self) -> Result<f32, FrameError> {
        let v = f32::from_bits(self.u32()?);
        if v.is_finite() {
            Ok(v)
        } else {
            Err(FrameError::BadPayload)
        }
    }
    /// A flag byte with only the bits in `mask` allowed.
    fn flags(&mut self, mask: u8) -> Result<u8, FrameError> {
        let f = self.u8()?;
        if f & !mask != 0 {
            return Err(FrameError::BadPayload);
        }
        Ok(f)
    }
}

fn payload_sensor(w: &mut Writer, s: &SensorFrame) {
    w.u32(s.seq);
    w.u32(s.t_us);
    let n = (s.n_edges as usize).min(MAX_EDGES);
    w.u8(n as u8);
    for e in &s.edges[..n] {
        w.u8(match e.source {
            EdgeSource::CrankTooth => 0,
            EdgeSource::CamSync => 1,
        });
        w.u32(e.t_us);
    }
    for c in s.adc_counts {
        w.u16(c);
    }
    w.f32(s.valve.open_deg);
    w.f32(s.valve.close_deg);
    w.u8(s.valve.high_lift as u8 | (s.valve.soft_seat as u8) << 1 | (s.valve.enabled as u8) << 2);
    w.f32(s.cam_phase_set_deg);
    for x in s.vacuum_x_set_pct {
        w.f32(x);
    }
    w.u8(s.motor_driver_fault as u8);
}

fn payload_actuator(w: &mut Writer, a: &ActuatorFrame) {
    w.u32(a.seq);
    w.u32(a.t_us);
    let (code, duty) = match a.pilot {
        SolenoidCmd::Off => (0, 0.0),
        SolenoidCmd::Full => (1, 0.0),
        SolenoidCmd::Pwm(d) => (2, d),
    };
    w.u8(code);
    w.f32(duty);
    w.u8(a.lift_valve_on as u8 | (a.snubber_on as u8) << 1 | (a.pump_on as u8) << 2);
    w.f32(a.motor_duty);
    for d in a.vacuum_duty {
        w.f32(d);
    }
    w.u32(a.faults);
    w.u32(a.bad_frames);
}

fn payload_nack(w: &mut Writer, n: &Nack) {
    w.u32(n.seq_expected);
    w.u32(n.bad_frames);
    w.u8(n.reason);
}

/// Encodes `frame` into `out`; returns the number of bytes written.
pub fn encode(frame: &Frame, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut w = Writer {
        buf: out,
        at: 0,
        overflow: false,
    };
    w.bytes(&SYNC);
    w.u8(FRAME_VERSION);
    let kind = match frame {
        Frame::Sensor(_) => FrameKind::Sensor,
        Frame::Actuator(_) => FrameKind::Actuator,
        Frame::Nack(_) => FrameKind::Nack,
    };
    w.u8(kind as u8);
    w.u8(0); // the length, patched below
    match frame {
        Frame::Sensor(s) => payload_sensor(&mut w, s),
        Frame::Actuator(a) => payload_actuator(&mut w, a),
        Frame::Nack(n) => payload_nack(&mut w, n),
    }
    if w.overflow {
        return Err(FrameError::BufferTooSmall);
    }
    let end = w.at;
    let payload_len = end - HEADER_BYTES;
    let buf = w.buf;
    buf[4] = payload_len as u8;
    let crc = crc16(&buf[2..end]);
    match buf.get_mut(end..end + CRC_BYTES) {
        Some(dst) => dst.copy_from_slice(&crc.to_le_bytes()),
        None => return Err(FrameError::BufferTooSmall),
    }
    Ok(end + CRC_BYTES)
}

/// Decodes one complete frame (sync word to CRC).
pub fn decode(bytes: &[u8]) -> Result<Frame, FrameError> {
    if bytes.len() < HEADER_BYTES + CRC_BYTES || bytes[..2] != SYNC {
        return Err(FrameError::BadLength);
    }
    let payload_len = bytes[4] as usize;
    if payload_len > MAX_PAYLOAD_BYTES || bytes.len() != HEADER_BYTES + payload_len + CRC_BYTES {
        return Err(FrameError::BadLength);
    }
    let end = HEADER_BYTES + payload_len;
    let crc = u16::from_le_bytes([bytes[end], bytes[end + 1]]);
    if crc16(&bytes[2..end]) != crc {
        return Err(FrameError::BadCrc);
    }
    if bytes[2] != FRAME_VERSION {
        return Err(FrameError::BadVersion);
    }
    let mut r = Reader {
        buf: &bytes[HEADER_BYTES..end],
        at: 0,
    };
    let frame = match bytes[3] {
        k if k == FrameKind::Sensor as u8 => Frame::Sensor(read_sensor(&mut r)?),
        k if k == FrameKind::Actuator as u8 => {
            if payload_len != ACTUATOR_BYTES {
                return Err(FrameError::BadLength);
            }
            Frame::Actuator(read_actuator(&mut r)?)
        }
        k if k == FrameKind::Nack as u8 => {
            if payload_len != NACK_BYTES {
                return Err(FrameError::BadLength);
            }
            Frame::Nack(Nack {
                seq_expected: r.u32()?,
                bad_frames: r.u32()?,
                reason: r.u8()?,
            })
        }
        _ => return Err(FrameError::BadKind),
    };
    if r.at != payload_len {
        return Err(FrameError::BadLength);
    }
    Ok(frame)
}

fn read_sensor(r: &mut Reader) -> Result<SensorFrame, FrameError> {
    let seq = r.u32()?;
    let t_us = r.u32()?;
    let n_edges = r.u8()?;
    if n_edges as usize > MAX_EDGES {
        return Err(FrameError::BadPayload);
    }
    if r.buf.len() != SENSOR_FIXED_BYTES + 5 * n_edges as usize {
        return Err(FrameError::BadLength);
    }
    let mut edges = [SensorFrame::NO_EDGE; MAX_EDGES];
    for e in edges.iter_mut().take(n_edges as usize) {
        let source = match r.u8()? {
            0 => EdgeSource::CrankTooth,
            1 => EdgeSource::CamSync,
            _ => return Err(FrameError::BadPayload),
        };
        *e = Edge { source, t_us: r.u32()? };
    }
    let mut adc_counts = [0u16; N_CHANNELS];
    for c in adc_counts.iter_mut() {
        *c = r.u16()?;
        if *c > 4095 {
            return Err(FrameError::BadPayload);
        }
    }
    let open_deg = r.f32()?;
    let close_deg = r.f32()?;
    let f = r.flags(0b111)?;
    let valve = ValveRequest {
        open_deg,
        close_deg,
        high_lift: f & 1 != 0,
        soft_seat: f & 2 != 0,
        enabled: f & 4 != 0,
    };
    let cam_phase_set_deg = r.f32()?;
    let vacuum_x_set_pct = [r.f32()?, r.f32()?, r.f32()?];
    let motor_driver_fault = r.flags(1)? != 0;
    Ok(SensorFrame {
        seq,
        t_us,
        n_edges,
        edges,
        adc_counts,
        valve,
        cam_phase_set_deg,
        vacuum_x_set_pct,
        motor_driver_fault,
    })
}

fn read_actuator(r: &mut Reader) -> Result<ActuatorFrame, FrameError> {
    let seq = r.u32()?;
    let t_us = r.u32()?;
    let code = r.u8()?;
    let duty = r.f32()?;
    let pilot = match code {
        0 => SolenoidCmd::Off,
        1 => SolenoidCmd::Full,
        2 if (0.0..=1.0).contains(&duty) => SolenoidCmd::Pwm(duty),
        _ => return Err(FrameError::BadPayload),
    };
    let f = r.flags(0b111)?;
    let motor_duty = r.f32()?;
    let vacuum_duty = [r.f32()?, r.f32()?, r.f32()?];
    if !(0.0..=1.0).contains(&motor_duty) || vacuum_duty.iter().any(|d| !(0.0..=1.0).contains(d)) {
        return Err(FrameError::BadPayload);
    }
    Ok(ActuatorFrame {
        seq,
        t_us,
        pilot,
        lift_valve_on: f & 1 != 0,
        snubber_on: f & 2 != 0,
        motor_duty,
        vacuum_duty,
        pump_on: f & 4 != 0,
        faults: r.u32()?,
        bad_frames: r.u32()?,
    })
}

/// Byte-stream decoder: feed bytes as they arrive (a UART without idle-line detection);
/// junk before a sync word is skipped, and after a bad frame the search restarts one byte
/// after its sync word, so a frame hidden in a corrupted one's bytes is still found.
#[derive(Clone, Debug)]
pub struct FrameDecoder {
    buf: [u8; MAX_FRAME_BYTES],
    len: usize,
    /// Bytes skipped while looking for a sync word.
    pub junk_bytes: u32,
}

impl Default for FrameDecoder {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameDecoder {
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_FRAME_BYTES],
            len: 0,
            junk_bytes: 0,
        }
    }

    /// Adds one byte; returns a result when a frame completed or was found bad. After a
    /// `Some`, call [`Self::poll`] until it returns `None`: the buffered bytes may hold more.
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame, FrameError>> {
        if self.len == MAX_FRAME_BYTES {
            // Cannot happen (a frame's length is bounded and checked before this), but a full
            // buffer must not stall the decoder: drop the oldest byte.
            self.discard(1);
        }
        self.buf[self.len] = byte;
        self.len += 1;
        self.poll()
    }

    /// Examines the buffered bytes without adding one.
    pub fn poll(&mut self) -> Option<Result<Frame, FrameError>> {
        let skip = (0..self.len)
            .find(|&i| self.buf[i] == SYNC[0] && (i + 1 == self.len || self.buf[i + 1] == SYNC[1]))
            .unwrap_or(self.len);
        if skip > 0 {
            self.junk_bytes = self.junk_bytes.wrapping_add(skip as u32);
            self.discard(skip);
        }
        if self.len < HEADER_BYTES {
            return None;
        }
        let payload_len = self.buf[4] as usize;
        if payload_len > MAX_PAYLOAD_BYTES {
            self.discard(1);
            return Some(Err(FrameError::BadLength));
        }
        let total = HEADER_BYTES + payload_len + CRC_BYTES;
        if self.len < total {
            return None;
        }
        let result = decode(&self.buf[..total]);
        self.discard(if result.is_ok() { total } else { 1 });
        Some(result)
    }

    /// Bytes waiting (an incomplete frame).
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Forgets buffered bytes (after a link timeout).
    pub fn clear(&mut self) {
        self.len = 0;
    }

    fn discard(&mut self, n: usize) {
        let n = n.min(self.len);
        self.buf.copy_within(n..self.len, 0);
        self.len -= n;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn sensor(seq: u32, n_edges: u8) -> SensorFrame {
        let mut edges = [SensorFrame::NO_EDGE; MAX_EDGES];
        for (k, e) in edges.iter_mut().enumerate().take(n_edges as usize) {
            *e = Edge {
                source: if k % 3 == 2 {
                    EdgeSource::CamSync
                } else {
                    EdgeSource::CrankTooth
                },
                t_us: 1000 + 7 * k as u32,
            };
        }
        SensorFrame {
            seq,
            t_us: 4_294_967_000u32.wrapping_add(seq * 50),
            n_edges,
            edges,
            adc_counts: [0, 1, 2048, 4095, 17, 300, 1000, 2000, 3000, 4000],
            valve: ValveRequest {
                open_deg: 360.25,
                close_deg: 540.0,
                high_lift: true,
                soft_seat: false,
                enabled: true,
            },
            cam_phase_set_deg: 12.5,
            vacuum_x_set_pct: [20.0, -0.0, 1e-7],
            motor_driver_fault: true,
        }
    }

    fn actuator(seq: u32) -> ActuatorFrame {
        ActuatorFrame {
            seq,
            t_us: 123,
            pilot: SolenoidCmd::Pwm(0.3125),
            lift_valve_on: true,
            snubber_on: false,
            motor_duty: 0.25,
            vacuum_duty: [0.0, 0.5, 1.0],
            pump_on: true,
            faults: 0x8001,
            bad_frames: 7,
        }
    }

    fn bytes_of(f: &Frame) -> ([u8; MAX_FRAME_BYTES], usize) {
        let mut buf = [0u8; MAX_FRAME_BYTES];
        let n = encode(f, &mut buf).unwrap();
        (buf, n)
    }

    fn feed(dec: &mut FrameDecoder, bytes: &[u8]) -> ([Option<Result<Frame, FrameError>>; 8], usize) {
        let mut out = [None; 8];
        let mut k = 0;
        for &b in bytes {
            let mut r = dec.push(b);
            while let Some(x) = r {
                if k < out.len() {
                    out[k] = Some(x);
                }
                k += 1;
                r = dec.poll();
            }
        }
        (out, k)
    }

    #[test]
    fn crc_check_value() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
    }

    #[test]
    fn sizes_are_within_bounds() {
        let (_, n) = bytes_of(&Frame::Sensor(sensor(1, MAX_EDGES as u8)));
        assert_eq!(n, MAX_FRAME_BYTES);
        assert!(MAX_PAYLOAD_BYTES <= u8::MAX as usize);
        let (_, n) = bytes_of(&Frame::Actuator(actuator(1)));
        assert_eq!(n, HEADER_BYTES + ACTUATOR_BYTES + CRC_BYTES);
        let mut small = [0u8; 20];
        assert_eq!(
            encode(&Frame::Actuator(actuator(1)), &mut small),
            Err(FrameError::BufferTooSmall)
        );
    }

    #[test]
    fn round_trip_every_kind_bit_exact() {
        for f in [
            Frame::Sensor(sensor(5, 0)),
            Frame::Sensor(sensor(6, 3)),
            Frame::Actuator(actuator(9)),
            Frame::Actuator(ActuatorFrame {
                pilot: SolenoidCmd::Full,
                ..actuator(10)
            }),
            Frame::Nack(Nack {
                seq_expected: 11,
                bad_frames: 2,
                reason: FrameError::BadCrc as u8,
            }),
        ] {
            let (buf, n) = bytes_of(&f);
            let back = decode(&buf[..n]).unwrap();
            assert_eq!(back, f);
            if let (Frame::Sensor(a), Frame::Sensor(b)) = (f, back) {
                // -0.0 == 0.0 in PartialEq: check the bits too.
                assert_eq!(a.vacuum_x_set_pct[1].to_bits(), b.vacuum_x_set_pct[1].to_bits());
            }
        }
    }

    #[test]
    fn each_check_rejects_its_fault() {
        let (good, n) = bytes_of(&Frame::Actuator(actuator(1)));
        // Any single flipped bit after the sync word: the CRC catches it (or the length check
        // when the length byte itself is hit).
        for i in 2..n {
            for bit in 0..8 {
                let mut b = good;
                b[i] ^= 1 << bit;
                let e = decode(&b[..n]).unwrap_err();
                assert!(
                    matches!(e, FrameError::BadCrc | FrameError::BadLength),
                    "byte {i} bit {bit}: {e:?}"
                );
            }
        }
        // Re-signed frames with bad content: each field check fires.
        let resign = |mut b: [u8; MAX_FRAME_BYTES], n: usize| {
            let crc = crc16(&b[2..n - 2]).to_le_bytes();
            b[n - 2] = crc[0];
            b[n - 1] = crc[1];
            decode(&b[..n])
        };
        let mut b = good;
        b[2] = FRAME_VERSION + 1;
        assert_eq!(resign(b, n), Err(FrameError::BadVersion));
        let mut b = good;
        b[3] = 9;
        assert_eq!(resign(b, n), Err(FrameError::BadKind));
        let mut b = good;
        b[HEADER_BYTES + 8] = 3; // pilot code
        assert_eq!(resign(b, n), Err(FrameError::BadPayload));
        let mut b = good;
        b[HEADER_BYTES + 13] = 0x08; // unknown flag bit
        assert_eq!(resign(b, n), Err(FrameError::BadPayload));
        let mut b = good;
        b[HEADER_BYTES + 14..HEADER_BYTES + 18].copy_from_slice(&f32::NAN.to_bits().to_le_bytes()); // motor duty
        assert_eq!(resign(b, n), Err(FrameError::BadPayload));
        let mut b = good;
        b[HEADER_BYTES + 14..HEADER_BYTES + 18].copy_from_slice(&1.5f32.to_bits().to_le_bytes());
        assert_eq!(resign(b, n), Err(FrameError::BadPayload));
        // A sensor frame claiming more edges than it carries.
        let (s, m) = bytes_of(&Frame::Sensor(sensor(1, 2)));
        let mut b = s;
        b[HEADER_BYTES + 8] = 3;
        assert_eq!(resign(b, m), Err(FrameError::BadLength));
        let mut b = s;
        b[HEADER_BYTES + 8] = MAX_EDGES as u8 + 1;
        assert_eq!(resign(b, m), Err(FrameError::BadPayload));
    }

    #[test]
    fn decoder_skips_junk_and_finds_frames_after_a_bad_one() {
        let (a, na) = bytes_of(&Frame::Actuator(actuator(1)));
        let (s, ns) = bytes_of(&Frame::Sensor(sensor(2, 1)));
        let mut stream = [0u8; 3 * MAX_FRAME_BYTES];
        let mut k = 0;
        for &b in [0x00u8, 0x55, 0x12, 0xEC].iter().chain(&a[..na]) {
            stream[k] = b;
            k += 1;
        }
        // A corrupted copy of `a` (one byte flipped), then a good sensor frame.
        let mut bad = a;
        bad[10] ^= 0x40;
        stream[k..k + na].copy_from_slice(&bad[..na]);
        k += na;
        stream[k..k + ns].copy_from_slice(&s[..ns]);
        k += ns;
        let mut dec = FrameDecoder::new();
        let (out, count) = feed(&mut dec, &stream[..k]);
        assert_eq!(count, 3, "{out:?}");
        assert_eq!(out[0], Some(Ok(Frame::Actuator(actuator(1)))));
        assert_eq!(out[1], Some(Err(FrameError::BadCrc)));
        assert_eq!(out[2], Some(Ok(Frame::Sensor(sensor(2, 1)))));
        assert_eq!(dec.pending(), 0);
        assert_eq!(
            dec.junk_bytes as usize,
            4 + (na - 1),
            "junk before the first frame and the rest of the bad one"
        );
    }

    #[test]
    fn a_huge_length_byte_is_rejected_at_once() {
        let mut dec = FrameDecoder::new();
        let (out, count) = feed(&mut dec, &[0x55, 0xEC, FRAME_VERSION, 1, 250]);
        assert_eq!(count, 1);
        assert_eq!(out[0], Some(Err(FrameError::BadLength)));
    }

    proptest! {
        /// Whatever the line delivers, the decoder never panics, never returns more results
        /// than bytes, and any frame it accepts re-encodes to valid bytes.
        #[test]
        fn decoder_survives_random_bytes(bytes in proptest::collection::vec(any::<u8>(), 0..600)) {
            let mut dec = FrameDecoder::new();
            let mut results = 0usize;
            for &b in &bytes {
                let mut r = dec.push(b);
                while let Some(x) = r {
                    results += 1;
                    if let Ok(f) = x {
                        let (buf, n) = bytes_of(&f);
                        prop_assert_eq!(decode(&buf[..n]), Ok(f));
                    }
                    r = dec.poll();
                }
            }
            prop_assert!(results <= bytes.len());
            prop_assert!(dec.pending() <= MAX_FRAME_BYTES);
        }

        /// Frames survive any split of the stream (bytes arrive one by one in any case) and
        /// random junk between them.
        #[test]
        fn frames_between_junk_all_arrive(seqs in proptest::collection::vec(any::<u32>(), 1..6), junk in proptest::collection::vec(0u8..0x55, 0..20)) {
            let mut dec = FrameDecoder::new();
            let mut got = 0;
            for (k, &seq) in seqs.iter().enumerate() {
                for &j in &junk {
                    prop_assert!(dec.push(j).is_none());
                }
                let f = if k % 2 == 0 { Frame::Sensor(sensor(seq % 1000, (k % 4) as u8)) } else { Frame::Actuator(actuator(seq)) };
                let (buf, n) = bytes_of(&f);
                for (i, &b) in buf[..n].iter().enumerate() {
                    let r = dec.push(b);
                    if i + 1 < n {
                        prop_assert!(r.is_none());
                    } else {
                        prop_assert_eq!(r, Some(Ok(f)));
                        got += 1;
                    }
                }
            }
            prop_assert_eq!(got, seqs.len());
        }
    }
}
