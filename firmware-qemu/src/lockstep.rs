//! The lockstep server: sensor frames in over the link, [`EcuCore::step`], actuator frames out.
//!
//! - A frame that fails a check (length, CRC, version, kind, field) is counted and answered
//!   with a [`Nack`]; nothing in it is used, the outputs stay as they were.
//! - A sensor frame with the `seq` just stepped is the host's retransmission (our answer was
//!   lost or late): it gets the previous answer again, without stepping twice.
//! - No valid frame for [`LINK_TIMEOUT`]: the outputs go to [`EcuCore::safe_outputs`], which
//!   is sent once, unasked, as an actuator frame whose `t_us` is the ECU's own estimate of the
//!   time (never the `t_us` of a sensor frame, so the host cannot take it for an answer).
use embassy_time::{with_deadline, Duration, Instant};
use model_core::ecu::frame::{
    encode, ActuatorFrame, Frame, FrameDecoder, FrameError, Nack, SensorFrame, MAX_FRAME_BYTES,
};
use model_core::ecu::lockstep::EcuCore;

use crate::board::Link;

/// Silence on the link after which the outputs go safe (emulated time; see `board::systick_time`).
pub const LINK_TIMEOUT: Duration = Duration::from_millis(100);
/// Silence after which the host is taken to be gone and QEMU is ended (semihosting exit), so
/// an emulator whose host died does not run on forever.
pub const HOST_GONE: Duration = Duration::from_secs(10);

/// The link state around the ECU core.
pub struct Server {
    core: EcuCore,
    /// Frames rejected since start.
    bad_frames: u32,
    /// The last answer to a sensor frame (the one a retransmission gets again).
    last_answer: Option<ActuatorFrame>,
    /// What the outputs are now: the last answer, or the safe state after a timeout.
    outputs: ActuatorFrame,
}

impl Server {
    pub fn new(core: EcuCore) -> Self {
        Self {
            core,
            bad_frames: 0,
            last_answer: None,
            outputs: EcuCore::safe_outputs(0, 0),
        }
    }

    /// The answer to one decoder result.
    pub fn on_frame(
        &mut self,
        decoded: Result<Frame, FrameError>,
        step: &mut impl FnMut(&mut EcuCore, &SensorFrame) -> ActuatorFrame,
    ) -> Frame {
        match decoded {
            Ok(Frame::Sensor(s)) => {
                let answer = match self.last_answer {
                    Some(last) if last.seq == s.seq => last,
                    _ => step(&mut self.core, &s),
                };
                let answer = ActuatorFrame {
                    bad_frames: self.bad_frames,
                    ..answer
                };
                self.last_answer = Some(answer);
                self.outputs = answer;
                Frame::Actuator(answer)
            }
            // A well-formed frame of a kind the ECU never receives.
            Ok(Frame::Actuator(_) | Frame::Nack(_)) => self.reject(FrameError::BadKind),
            Err(e) => self.reject(e),
        }
    }

    fn reject(&mut self, why: FrameError) -> Frame {
        self.bad_frames = self.bad_frames.wrapping_add(1);
        let seq_expected = self.last_answer.map_or(0, |a| a.seq.wrapping_add(1));
        Frame::Nack(Nack {
            seq_expected,
            bad_frames: self.bad_frames,
            reason: why as u8,
        })
    }

    /// The link fell silent `silent_us` after the last valid frame: outputs safe, and the
    /// report of it.
    pub fn on_silence(&mut self, silent_us: u32) -> Frame {
        let (seq, t_us) = self.last_answer.map_or((0, 0), |a| (a.seq, a.t_us));
        let safe = ActuatorFrame {
            bad_frames: self.bad_frames,
            ..EcuCore::safe_outputs(seq, t_us.wrapping_add(silent_us))
        };
        self.outputs = safe;
        Frame::Actuator(safe)
    }
}

/// Serves the link forever. `step` runs the core on one sensor frame (plain [`EcuCore::step`],
/// or with instruction-count markers around it in the bench mode).
pub async fn serve(
    link: &mut Link,
    server: &mut Server,
    mut step: impl FnMut(&mut EcuCore, &SensorFrame) -> ActuatorFrame,
) -> ! {
    let mut decoder = FrameDecoder::new();
    let mut out = [0u8; MAX_FRAME_BYTES];
    let mut last_valid = Instant::now();
    let mut silent = false;
    loop {
        let byte = if silent {
            match with_deadline(last_valid + HOST_GONE, link.read_byte()).await {
                Ok(b) => b,
                Err(_) => {
                    defmt::warn!("no host for {=u64} s: ending the emulation", HOST_GONE.as_secs());
                    semihosting::process::exit(0)
                }
            }
        } else {
            match with_deadline(last_valid + LINK_TIMEOUT, link.read_byte()).await {
                Ok(b) => b,
                Err(_) => {
                    silent = true;
                    decoder.clear();
                    let silent_us = u32::try_from(last_valid.elapsed().as_micros()).unwrap_or(u32::MAX);
                    let report = server.on_silence(silent_us);
                    send(link, &report, &mut out);
                    defmt::warn!(
                        "link silent for {=u32} us: outputs safe ({=u32} bytes lost to a full buffer so far)",
                        silent_us,
                        crate::board::usart1::rx_dropped()
                    );
                    continue;
                }
            }
        };
        let mut next = decoder.push(byte);
        while let Some(decoded) = next {
            if matches!(decoded, Ok(Frame::Sensor(_))) {
                last_valid = Instant::now();
                silent = false;
            }
            let answer = server.on_frame(decoded, &mut step);
            send(link, &answer, &mut out);
            next = decoder.poll();
        }
    }
}

fn send(link: &mut Link, frame: &Frame, out: &mut [u8; MAX_FRAME_BYTES]) {
    // Every frame fits MAX_FRAME_BYTES (the encoder's bound); should it not, nothing is sent
    // and the host's retransmission timer takes over.
    if let Ok(n) = encode(frame, out) {
        link.write(&out[..n]);
    }
}
