//! `hil-host pil`: processor in the loop. The ECU core runs as firmware (`firmware-qemu`) on
//! QEMU's emulated STM32F405 board (`netduinoplus2`); each lockstep step the host sends the
//! sensor frame over the emulated USART1 (a TCP socket on the host side) and waits for the
//! actuator frame.
//!
//! The link is lossless above a lossy line: a Nack (the firmware rejected a frame) or no
//! answer within [`PilOptions::answer_timeout`] (doubling while it lasts) makes the host send the same frame again; the
//! firmware answers a repeated `seq` with its previous answer without stepping twice. Frames
//! that fail the host's checks are counted and never used. [`LinkFaults`] injects corrupted
//! and dropped sensor frames to exercise exactly that.
//!
//! QEMU is killed when the [`QemuBoard`] is dropped, on every path (errors and panics
//! included); should the host die without dropping it, the firmware ends QEMU itself after
//! 10 s of silence on the link (semihosting exit).

use std::io::{ErrorKind, Read, Write};
use std::path::Path;
use std::time::{Duration, Instant};

use model_core::ecu::frame::{encode, ActuatorFrame, Frame, FrameDecoder, FrameError, SensorFrame, MAX_FRAME_BYTES};
use model_core::ecu::lockstep::EcuCore;

mod qemu;
pub use qemu::*;

/// Faults injected on the host → ECU direction, counted over every transmission
/// (retransmissions included): the n-th, 2n-th, ... frame is corrupted (one payload byte
/// inverted: the CRC must catch it), the m-th, 2m-th, ... is not sent at all. A transmission
/// that is due for both is dropped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkFaults {
    pub corrupt_every: Option<u32>,
    pub drop_every: Option<u32>,
}

/// Counters of one PIL run, both directions.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Sensor frames answered (lockstep steps).
    pub steps: u64,
    /// Sensor frames put on the wire, retransmissions included (dropped ones not).
    pub transmissions: u64,
    pub corrupted_injected: u64,
    pub dropped_injected: u64,
    /// Nacks from the firmware (it rejected a frame).
    pub nacks_received: u64,
    /// Answers that did not come within the answer timeout.
    pub answer_timeouts: u64,
    /// Frames from the firmware that failed the host's checks (CRC, length, ...).
    pub bad_frames_received: u64,
    /// Actuator frames that answer no pending request (late answers to a retransmitted
    /// frame); discarded.
    pub stale_answers: u64,
    /// Unasked safe-state reports (the firmware's link timeout fired).
    pub safe_state_reports: u64,
    /// The firmware's own count of rejected frames, from its last answer.
    pub ecu_bad_frames: u32,
}

/// Options of a PIL link.
#[derive(Clone, Debug)]
pub struct PilOptions {
    pub qemu: QemuOptions,
    pub faults: LinkFaults,
    /// How long to wait for an answer before sending the frame again (doubled after each
    /// timeout of the same frame, up to 1 s: a stalled emulator is not flooded). Well below
    /// the firmware's 100 ms link timeout, so a dropped frame does not make its outputs go safe.
    pub answer_timeout: Duration,
    /// Transmissions of one frame before the run is given up (12 at 25 ms: about 8 s).
    pub max_attempts: u32,
}

impl Default for PilOptions {
    fn default() -> Self {
        Self {
            qemu: QemuOptions::default(),
            faults: LinkFaults::default(),
            answer_timeout: Duration::from_millis(25),
            max_attempts: 12,
        }
    }
}

/// What arrived while waiting for an answer.
enum Reply {
    Answer(ActuatorFrame),
    Nack,
    Timeout,
}

/// The ECU link over QEMU's serial port.
pub struct PilLink {
    board: QemuBoard,
    decoder: FrameDecoder,
    opts: PilOptions,
    stats: LinkStats,
    rx: [u8; 512],
    rx_len: usize,
    rx_at: usize,
    /// Safe-state reports received (in order), for the silent-link check.
    pub safe_reports: Vec<ActuatorFrame>,
}

impl PilLink {
    /// Starts QEMU with the firmware image `elf` and connects.
    pub fn start(elf: &Path, opts: PilOptions) -> Result<Self, String> {
        let board = QemuBoard::start(elf, &opts.qemu)?;
        Ok(Self {
            board,
            decoder: FrameDecoder::new(),
            opts,
            stats: LinkStats::default(),
            rx: [0; 512],
            rx_len: 0,
            rx_at: 0,
            safe_reports: Vec::new(),
        })
    }

    pub fn stats(&self) -> LinkStats {
        self.stats
    }

    pub fn board(&mut self) -> &mut QemuBoard {
        &mut self.board
    }

    /// One lockstep step: sends `sensors` until the firmware answers it.
    pub fn exchange(&mut self, sensors: &SensorFrame) -> Result<ActuatorFrame, String> {
        let mut wire = [0u8; MAX_FRAME_BYTES];
        let n = encode(&Frame::Sensor(*sensors), &mut wire)
            .map_err(|e| format!("encoding sensor frame {}: {e:?}", sensors.seq))?;
        let mut wait = self.opts.answer_timeout;
        for _ in 0..self.opts.max_attempts {
            self.transmit(&wire[..n])?;
            match self.wait_reply(sensors, wait)? {
                Reply::Answer(a) => {
                    self.stats.steps += 1;
                    self.stats.ecu_bad_frames = a.bad_frames;
                    return Ok(a);
                }
                Reply::Nack => self.stats.nacks_received += 1,
                Reply::Timeout => {
                    self.stats.answer_timeouts += 1;
                    wait = (wait * 2).min(Duration::from_secs(1));
                }
            }
        }
        Err(format!(
            "sensor frame {} unanswered after {} transmissions ({:?}); QEMU stderr: {}",
            sensors.seq,
            self.opts.max_attempts,
            self.stats,
            self.board.stderr_text().trim()
        ))
    }

    /// Sends one frame, or corrupts or drops it as the fault plan says.
    fn transmit(&mut self, frame: &[u8]) -> Result<(), String> {
        let k = self.stats.transmissions + self.stats.dropped_injected + 1;
        let due = |every: Option<u32>| every.is_some_and(|n| n > 0 && k.is_multiple_of(u64::from(n)));
        if due(self.opts.faults.drop_every) {
            self.stats.dropped_injected += 1;
            return Ok(());
        }
        self.stats.transmissions += 1;
        let stream = self.board.stream();
        if due(self.opts.faults.corrupt_every) {
            self.stats.corrupted_injected += 1;
            let mut bad = frame.to_vec();
            // A byte in the middle of the payload: header and CRC stay intact, so the
            // firmware sees one whole frame with a wrong CRC.
            let at = 5 + (frame.len() - 7) / 2;
            bad[at] ^= 0xFF;
            stream.write_all(&bad)
        } else {
            stream.write_all(frame)
        }
        .map_err(|e| format!("writing to {QEMU}'s serial port: {e}"))
    }

    /// Reads until the answer to `sent`, a Nack, or the answer timeout.
    fn wait_reply(&mut self, sent: &SensorFrame, wait: Duration) -> Result<Reply, String> {
        let deadline = Instant::now() + wait;
        loop {
            while let Some(decoded) = self.next_decoded() {
                match decoded {
                    Ok(Frame::Actuator(a)) if a.seq == sent.seq && a.t_us == sent.t_us => return Ok(Reply::Answer(a)),
                    Ok(Frame::Actuator(a)) => self.unasked(a),
                    Ok(Frame::Nack(_)) => return Ok(Reply::Nack),
                    Ok(Frame::Sensor(_)) | Err(_) => self.stats.bad_frames_received += 1,
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(Reply::Timeout);
            }
            if !self.fill(deadline - now)? {
                return Ok(Reply::Timeout);
            }
        }
    }

    fn unasked(&mut self, a: ActuatorFrame) {
        if a == (ActuatorFrame {
            bad_frames: a.bad_frames,
            ..EcuCore::safe_outputs(a.seq, a.t_us)
        }) {
            self.stats.safe_state_reports += 1;
            self.safe_reports.push(a);
        } else {
            self.stats.stale_answers += 1;
        }
    }

    /// The next decoder result from the bytes already received.
    fn next_decoded(&mut self) -> Option<Result<Frame, FrameError>> {
        if let Some(r) = self.decoder.poll() {
            return Some(r);
        }
        while self.rx_at < self.rx_len {
            let b = self.rx[self.rx_at];
            self.rx_at += 1;
            if let Some(r) = self.decoder.push(b) {
                return Some(r);
            }
        }
        None
    }

    /// Receives what is there within `wait`; false when nothing came.
    fn fill(&mut self, wait: Duration) -> Result<bool, String> {
        let stream = &mut self.board.stream;
        stream
            .set_read_timeout(Some(wait.max(Duration::from_micros(100))))
            .map_err(|e| e.to_string())?;
        match stream.read(&mut self.rx) {
            Ok(0) => Err(format!(
                "{QEMU} closed the serial connection; stderr: {}",
                self.board.stderr_text().trim()
            )),
            Ok(n) => {
                self.rx_len = n;
                self.rx_at = 0;
                Ok(true)
            }
            Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => Ok(false),
            Err(e) if e.kind() == ErrorKind::Interrupted => Ok(true),
            Err(e) => Err(format!("reading {QEMU}'s serial port: {e}")),
        }
    }

    /// Sends raw bytes as they are (a hand-made bad frame, say).
    pub fn send_raw(&mut self, bytes: &[u8]) -> Result<(), String> {
        self.board
            .stream()
            .write_all(bytes)
            .map_err(|e| format!("writing to {QEMU}'s serial port: {e}"))
    }

    /// The next frame (or decode error) from the firmware within `wait`.
    pub fn next_frame(&mut self, wait: Duration) -> Result<Option<Result<Frame, FrameError>>, String> {
        let deadline = Instant::now() + wait;
        loop {
            if let Some(decoded) = self.next_decoded() {
                return Ok(Some(decoded));
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(None);
            }
            self.fill(deadline - now)?;
        }
    }

    /// Sends nothing for `silence` and collects what the firmware reports meanwhile (its
    /// link timeout's safe state).
    pub fn stay_silent(&mut self, silence: Duration) -> Result<Vec<ActuatorFrame>, String> {
        let before = self.safe_reports.len();
        let deadline = Instant::now() + silence;
        loop {
            while let Some(decoded) = self.next_decoded() {
                match decoded {
                    Ok(Frame::Actuator(a)) => self.unasked(a),
                    Ok(_) | Err(_) => self.stats.bad_frames_received += 1,
                }
            }
            let now = Instant::now();
            if now >= deadline {
                return Ok(self.safe_reports[before..].to_vec());
            }
            self.fill(deadline - now)?;
        }
    }
}

/// The result of driving a link with a list of sensor frames.
#[derive(Clone, Debug)]
pub struct FramesRun {
    pub answers: Vec<ActuatorFrame>,
    pub wall_s: f64,
    pub stats: LinkStats,
}

impl FramesRun {
    pub fn steps_per_s(&self) -> f64 {
        self.answers.len() as f64 / self.wall_s.max(1e-9)
    }
}

/// Sends `frames` through a PIL link, one lockstep step each.
pub fn run_frames(link: &mut PilLink, frames: &[SensorFrame]) -> Result<FramesRun, String> {
    let start = Instant::now();
    let mut answers = Vec::with_capacity(frames.len());
    for f in frames {
        answers.push(link.exchange(f)?);
    }
    Ok(FramesRun {
        answers,
        wall_s: start.elapsed().as_secs_f64(),
        stats: link.stats(),
    })
}

/// The same frames through [`EcuCore`] natively.
pub fn run_frames_native(frames: &[SensorFrame]) -> Result<Vec<ActuatorFrame>, String> {
    let mut core = EcuCore::new(model_core::ecu::lockstep::EcuCoreConfig::default())
        .map_err(|e| format!("ECU core calibration: {e}"))?;
    Ok(frames.iter().map(|f| core.step(f)).collect())
}

/// A symbol of an ELF32 little-endian image (the firmware).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ElfSymbol {
    pub name: String,
    pub addr: u32,
    pub size: u32,
}

/// The symbol table of an ELF32 little-endian file (what the marker addresses come from).
pub fn elf_symbols(path: &Path) -> Result<Vec<ElfSymbol>, String> {
    let data = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let bad = |what: &str| format!("{}: not a 32-bit little-endian ELF file ({what})", path.display());
    let u16_at = |at: usize| data.get(at..at + 2).map(|b| u16::from_le_bytes([b[0], b[1]]));
    let u32_at = |at: usize| {
        data.get(at..at + 4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    if data.get(..6) != Some(&[0x7F, b'E', b'L', b'F', 1, 1]) {
        return Err(bad("header"));
    }
    let shoff = u32_at(0x20).ok_or_else(|| bad("e_shoff"))? as usize;
    let shentsize = u16_at(0x2E).ok_or_else(|| bad("e_shentsize"))? as usize;
    let shnum = u16_at(0x30).ok_or_else(|| bad("e_shnum"))? as usize;
    let section = |k: usize| -> Option<(u32, usize, usize, usize)> {
        let h = shoff + k * shentsize;
        Some((
            u32_at(h + 4)?,
            u32_at(h + 16)? as usize,
            u32_at(h + 20)? as usize,
            u32_at(h + 24)? as usize,
        ))
    };
    const SHT_SYMTAB: u32 = 2;
    let (_, sym_off, sym_size, strtab) = (0..shnum)
        .filter_map(section)
        .find(|s| s.0 == SHT_SYMTAB)
        .ok_or_else(|| format!("{}: no symbol table (stripped?)", path.display()))?;
    let (_, str_off, str_size, _) = section(strtab).ok_or_else(|| bad("string table"))?;
    let strings = data
        .get(str_off..str_off + str_size)
        .ok_or_else(|| bad("string table bounds"))?;
    let mut out = Vec::new();
    for at in (sym_off..sym_off + sym_size).step_by(16) {
        let (Some(name), Some(addr), Some(size)) = (u32_at(at), u32_at(at + 4), u32_at(at + 8)) else {
            return Err(bad("symbol bounds"));
        };
        let name = strings.get(name as usize..).unwrap_or(&[]);
        let name = &name[..name.iter().position(|&b| b == 0).unwrap_or(name.len())];
        if !name.is_empty() {
            out.push(ElfSymbol {
                name: String::from_utf8_lossy(name).into_owned(),
                addr,
                size,
            });
        }
    }
    Ok(out)
}

/// Instruction counts of one label over its intervals.
#[derive(Clone, Debug, PartialEq)]
pub struct CountStats {
    pub label: String,
    pub n: usize,
    pub mean: f64,
    pub min: u64,
    pub max: u64,
}

/// What `target-bench` measured.
#[derive(Clone, Debug)]
pub struct TargetBench {
    /// Per label, the marker overhead (the `empty` interval) subtracted.
    pub counts: Vec<CountStats>,
    /// Instructions of an empty interval (the call of the end marker).
    pub empty_overhead: u64,
    /// Final plant states, raw bits: f32, then Q16.16, each in `PlantBench::state` order
    /// ([`PLANT_NUMBERS`]).
    pub plant_bits_target: Vec<u64>,
    pub plant_bits_host: Vec<u64>,
    /// The lockstep part (the frames sent to count the tasks).
    pub lockstep: FramesRun,
    pub answers_equal_native: bool,
}

/// The number types of the plant bench, in the order of its state record: the name in
/// reports (`target-bench --json`: "f32", "fixed" = Q16.16) and the marker-label suffix.
pub const PLANT_NUMBERS: [(&str, &str); 2] = [("f32", "f32"), ("fixed", "fixed")];

/// The plant bench's final states computed natively, as raw bits (f32, Q16.16).
pub fn plant_bench_native() -> Result<Vec<u64>, String> {
    use model_core::plant_bench::{PlantBench, COUNTED_STEPS};
    use model_core::Real;
    fn run<R: Real>() -> Result<[R; model_core::plant_bench::N_STATE], String> {
        let mut b = PlantBench::<R>::new().map_err(str::to_string)?;
        // The firmware's order (firmware-qemu/src/bench.rs, `plants`).
        for _ in 0..COUNTED_STEPS {
            b.step_ehvva();
            b.step_ehvva_lpv();
            let rpm = b.next_engine_rpm();
            b.step_evvt(rpm);
            b.step_vacuum();
            b.step_positioner();
        }
        Ok(b.state())
    }
    let f = run::<f32>()?;
    let x = run::<model_core::Q16>()?;
    Ok(f.iter()
        .map(|v| u64::from(v.to_bits()))
        .chain(x.iter().map(|v| v.to_bits() as u64))
        .collect())
}

/// The per-address profile's file name in `target_bench`'s `log_dir`.
pub const BY_ADDRESS_FILE: &str = "insn-by-address.txt";

/// Runs the firmware's bench mode under the instruction-counting plugin: the plant steps,
/// then `frames` through the lockstep link with every task counted. With `by_address` the
/// plugin also writes `insn-by-address.txt` in `log_dir`: per counted label, the instructions
/// executed at each address (`label 0xADDRESS count`), for `addr2line -e ELF` to map to source
/// lines.
pub fn target_bench(
    elf: &Path,
    frames: &[SensorFrame],
    log_dir: &Path,
    by_address: bool,
) -> Result<TargetBench, String> {
    let plugin = plugin_path()?;
    if !plugin.is_file() {
        return Err(format!(
            "{}: missing; run tools/setup-qemu.sh (it builds the plugin with gcc)",
            plugin.display()
        ));
    }
    let symbols = elf_symbols(elf)?;
    let mut spec = plugin.display().to_string();
    for s in symbols.iter().filter(|s| s.name.starts_with("pil_begin_")) {
        spec.push_str(&format!(
            ",begin={}:{:#x}:{}",
            &s.name["pil_begin_".len()..],
            s.addr,
            s.size
        ));
    }
    let end = symbols
        .iter()
        .find(|s| s.name == "pil_end")
        .ok_or_else(|| format!("{}: no pil_end marker", elf.display()))?;
    std::fs::create_dir_all(log_dir).map_err(|e| format!("{}: {e}", log_dir.display()))?;
    let counts_file = log_dir.join("insn-counts.txt");
    spec.push_str(&format!(
        ",end={:#x}:{},out={}",
        end.addr,
        end.size,
        counts_file.display()
    ));
    if by_address {
        spec.push_str(&format!(",pcs={}", log_dir.join(BY_ADDRESS_FILE).display()));
    }
    let qemu = QemuOptions {
        args: vec!["bench".into()],
        plugin: Some(spec),
        log_dir: Some(log_dir.to_path_buf()),
        calibration: None,
    };
    // Counting every instruction slows the emulation: generous answer timeout.
    let mut link = PilLink::start(
        elf,
        PilOptions {
            qemu,
            answer_timeout: Duration::from_millis(500),
            ..PilOptions::default()
        },
    )?;
    let plant_bits_target = read_plant_record(&mut link)?;
    let lockstep = run_frames(&mut link, frames)?;
    drop(link);
    let native = run_frames_native(frames)?;
    let answers_equal_native = native
        .iter()
        .zip(&lockstep.answers)
        .all(|(n, p)| *n == ActuatorFrame { bad_frames: 0, ..*p })
        && native.len() == lockstep.answers.len();

    let text = std::fs::read_to_string(&counts_file).map_err(|e| format!("{}: {e}", counts_file.display()))?;
    let mut by_label: Vec<(String, Vec<u64>)> = Vec::new();
    for (k, line) in text.lines().enumerate() {
        let mut it = line.split_whitespace();
        let (Some(label), Some(count), None) = (it.next(), it.next(), it.next()) else {
            return Err(format!("{}:{}: expected `label count`", counts_file.display(), k + 1));
        };
        let count: u64 = count
            .parse()
            .map_err(|_| format!("{}:{}: bad count {count}", counts_file.display(), k + 1))?;
        match by_label.iter_mut().find(|(l, _)| l == label) {
            Some((_, v)) => v.push(count),
            None => by_label.push((label.to_string(), vec![count])),
        }
    }
    let empty_overhead = by_label
        .iter()
        .find(|(l, _)| l == "empty")
        .and_then(|(_, v)| v.iter().min().copied())
        .ok_or_else(|| format!("{}: no `empty` interval", counts_file.display()))?;
    let counts = by_label
        .into_iter()
        .filter(|(l, _)| l != "empty")
        .map(|(label, v)| {
            let v: Vec<u64> = v.iter().map(|c| c.saturating_sub(empty_overhead)).collect();
            CountStats {
                label,
                n: v.len(),
                mean: v.iter().sum::<u64>() as f64 / v.len() as f64,
                min: v.iter().copied().min().unwrap_or(0),
                max: v.iter().copied().max().unwrap_or(0),
            }
        })
        .collect();
    Ok(TargetBench {
        counts,
        empty_overhead,
        plant_bits_target,
        plant_bits_host: plant_bench_native()?,
        lockstep,
        answers_equal_native,
    })
}

/// The bench's plant-state record (`firmware-qemu/src/bench.rs`): magic 0x50 0xB7, a word
/// count, the words (u64 LE), CRC-16/CCITT-FALSE over count and words.
fn read_plant_record(link: &mut PilLink) -> Result<Vec<u64>, String> {
    const MAGIC: [u8; 2] = [0x50, 0xB7];
    let words = PLANT_NUMBERS.len() * model_core::plant_bench::N_STATE;
    let total = 3 + 8 * words + 2;
    let mut buf: Vec<u8> = Vec::new();
    let stream = link.board().stream();
    // The plant steps run under the plugin first: seconds, not minutes.
    stream
        .set_read_timeout(Some(Duration::from_secs(60)))
        .map_err(|e| e.to_string())?;
    let mut chunk = [0u8; 256];
    loop {
        if let Some(at) = buf.windows(2).position(|w| w == MAGIC) {
            if buf.len() >= at + total {
                let rec = &buf[at..at + total];
                let crc = u16::from_le_bytes([rec[total - 2], rec[total - 1]]);
                if rec[2] as usize != words || model_core::ecu::frame::crc16(&rec[2..total - 2]) != crc {
                    return Err("the plant-state record from the target is corrupt".into());
                }
                return Ok((0..words)
                    .map(|k| u64::from_le_bytes(rec[3 + 8 * k..11 + 8 * k].try_into().unwrap_or([0; 8])))
                    .collect());
            }
        }
        let n = stream
            .read(&mut chunk)
            .map_err(|e| format!("waiting for the plant bench's record: {e}"))?;
        if n == 0 {
            return Err("QEMU closed the link before the plant bench's record".into());
        }
        buf.extend_from_slice(&chunk[..n]);
    }
}

impl crate::run::EcuLink for PilLink {
    fn exchange(&mut self, sensors: &SensorFrame) -> Result<ActuatorFrame, String> {
        PilLink::exchange(self, sensors)
    }
}

/// A scenario run on the emulated board.
#[derive(Clone, Debug)]
pub struct PilRun {
    pub output: crate::run::RunOutput,
    pub stats: LinkStats,
    pub wall_s: f64,
    /// With a native comparison: the steps compared and the first that differs.
    pub compared_steps: Option<usize>,
    pub first_difference: Option<(usize, ActuatorFrame, ActuatorFrame)>,
}

impl PilRun {
    pub fn steps_per_s(&self) -> f64 {
        self.stats.steps as f64 / self.wall_s.max(1e-9)
    }

    /// The summary lines of the PIL part (speed, link counters, native comparison).
    pub fn text(&self) -> String {
        let s = &self.stats;
        let mut t = format!(
            "PIL on {MACHINE}: {} lockstep steps in {:.1} s wall = {:.0} steps/s ({:.4} simulated s per wall s)\n\
             link: {} transmissions, {} corrupted and {} dropped by injection, {} Nacks, {} answer timeouts, \
             {} bad frames from the ECU, {} stale answers, {} safe-state reports; the ECU counted {} bad frames\n",
            s.steps,
            self.wall_s,
            self.steps_per_s(),
            self.steps_per_s() * f64::from(model_core::ecu::lockstep::STEP_US) * 1e-6,
            s.transmissions,
            s.corrupted_injected,
            s.dropped_injected,
            s.nacks_received,
            s.answer_timeouts,
            s.bad_frames_received,
            s.stale_answers,
            s.safe_state_reports,
            s.ecu_bad_frames,
        );
        match (self.compared_steps, &self.first_difference) {
            (Some(n), None) => t.push_str(&format!("native run: all {n} actuator frames bit-identical\n")),
            (Some(n), Some((k, a, b))) => t.push_str(&format!(
                "native run: {n} steps compared, first difference at step {k}:\n  native {a:?}\n  PIL    {b:?}\n"
            )),
            _ => {}
        }
        t
    }
}

/// Runs `scenario` with the ECU core on QEMU (closed loop through [`crate::run::run_with`]);
/// with `compare_native`, also natively, and compares every actuator frame.
pub fn run_scenario(
    scenario: &crate::run::Scenario,
    elf: &Path,
    faults: LinkFaults,
    until_s: Option<f64>,
    compare_native: bool,
    log_dir: &Path,
) -> Result<PilRun, String> {
    let unit = crate::run::Unit::default();
    run_scenario_calibrated(scenario, elf, faults, until_s, compare_native, log_dir, None, &unit)
}

/// [`run_scenario`] with a calibration image in the emulated ECU's calibration sector (the
/// native comparison runs the same image's configuration; an image the host refuses is not
/// sent) and the plants of `unit`.
#[allow(clippy::too_many_arguments)]
pub fn run_scenario_calibrated(
    scenario: &crate::run::Scenario,
    elf: &Path,
    faults: LinkFaults,
    until_s: Option<f64>,
    compare_native: bool,
    log_dir: &Path,
    calibration: Option<&Path>,
    unit: &crate::run::Unit,
) -> Result<PilRun, String> {
    let native_cfg = match calibration {
        Some(c) => crate::calibrate::ecu_config_from_image(c)?,
        None => model_core::ecu::lockstep::EcuCoreConfig::default(),
    };
    run_scenario_image(
        scenario,
        elf,
        faults,
        (until_s, compare_native),
        log_dir,
        (calibration, native_cfg),
        unit,
    )
}

/// The PIL run with `image` loaded as it is (even one the host would refuse: the firmware's
/// own fall-back is then what runs) and `native_cfg` for the native comparison.
pub fn run_scenario_image(
    scenario: &crate::run::Scenario,
    elf: &Path,
    faults: LinkFaults,
    (until_s, compare_native): (Option<f64>, bool),
    log_dir: &Path,
    (image, native_cfg): (Option<&Path>, model_core::ecu::lockstep::EcuCoreConfig),
    unit: &crate::run::Unit,
) -> Result<PilRun, String> {
    use crate::run::{run_with_unit, NativeLink, RunOptions};
    let opts = RunOptions {
        until_s,
        keep_frames: compare_native,
    };
    let qemu = QemuOptions {
        log_dir: Some(log_dir.to_path_buf()),
        calibration: image.map(Path::to_path_buf),
        ..QemuOptions::default()
    };
    let mut link = PilLink::start(
        elf,
        PilOptions {
            qemu,
            faults,
            ..PilOptions::default()
        },
    )?;
    let start = Instant::now();
    let output = run_with_unit(scenario, &mut link, &opts, unit)?;
    let wall_s = start.elapsed().as_secs_f64();
    let stats = link.stats();
    drop(link);
    let (mut compared_steps, mut first_difference) = (None, None);
    if compare_native {
        let native = run_with_unit(scenario, &mut NativeLink::with_config(native_cfg)?, &opts, unit)?;
        compared_steps = Some(native.frames.len().min(output.frames.len()));
        first_difference = native
            .frames
            .iter()
            .zip(&output.frames)
            .enumerate()
            .find(|(_, ((_, n), (_, p)))| *n != ActuatorFrame { bad_frames: 0, ..*p })
            .map(|(k, ((_, n), (_, p)))| (k, *n, *p));
        if native.frames.len() != output.frames.len() && first_difference.is_none() {
            return Err(format!(
                "native run has {} steps, PIL run {}",
                native.frames.len(),
                output.frames.len()
            ));
        }
    }
    Ok(PilRun {
        output,
        stats,
        wall_s,
        compared_steps,
        first_difference,
    })
}

impl TargetBench {
    /// Whether the target's final plant states of number type `k` ([`PLANT_NUMBERS`]) equal
    /// the host's bit for bit.
    pub fn plant_states_equal(&self, k: usize) -> bool {
        let n = model_core::plant_bench::N_STATE;
        let r = k * n..(k + 1) * n;
        self.plant_bits_target.get(r.clone()).is_some() && self.plant_bits_target[r.clone()] == self.plant_bits_host[r]
    }

    /// The mean instructions of one step of each plant in each number type of
    /// [`PLANT_NUMBERS`]: (plant id, number name, mean), in bench order.
    pub fn plant_steps(&self) -> Vec<(&'static str, &'static str, f64)> {
        let mut out = Vec::new();
        for plant in model_core::plant_bench::BenchPlant::ALL {
            for (name, suffix) in PLANT_NUMBERS {
                let label = format!("{}_plant_{suffix}", plant.label());
                if let Some(c) = self.counts.iter().find(|c| c.label == label) {
                    out.push((plant.id(), name, c.mean));
                }
            }
        }
        out
    }

    /// `{"plant_steps": [{"plant", "number", "instructions_mean", "min", "max"}, ...],
    /// "tasks": [{"task", "steps", "instructions_mean", "min", "max"}, ...]}`.
    pub fn to_json(&self) -> serde_json::Value {
        let stats = |label: &str| self.counts.iter().find(|c| c.label == label);
        let plant_steps: Vec<serde_json::Value> = self
            .plant_steps()
            .into_iter()
            .map(|(plant, number, mean)| {
                let suffix = PLANT_NUMBERS.iter().find(|(n, _)| *n == number).map_or(number, |p| p.1);
                let label = model_core::plant_bench::BenchPlant::ALL
                    .iter()
                    .find(|p| p.id() == plant)
                    .map(|p| format!("{}_plant_{suffix}", p.label()))
                    .unwrap_or_default();
                let c = stats(&label);
                serde_json::json!({
                    "plant": plant,
                    "number": number,
                    "instructions_mean": mean,
                    "instructions_min": c.map(|c| c.min),
                    "instructions_max": c.map(|c| c.max),
                    "steps": c.map(|c| c.n),
                })
            })
            .collect();
        let tasks: Vec<serde_json::Value> = self
            .counts
            .iter()
            .filter(|c| !c.label.contains("_plant_"))
            .map(|c| {
                serde_json::json!({
                    "task": c.label,
                    "steps": c.n,
                    "instructions_mean": c.mean,
                    "instructions_min": c.min,
                    "instructions_max": c.max,
                })
            })
            .collect();
        let equal: Vec<serde_json::Value> = PLANT_NUMBERS
            .iter()
            .enumerate()
            .map(|(k, (name, _))| serde_json::json!({"number": name, "target_equals_host": self.plant_states_equal(k)}))
            .collect();
        serde_json::json!({
            "plant_steps": plant_steps,
            "tasks": tasks,
            "plant_states": equal,
            "lockstep_answers_equal_native": self.answers_equal_native,
        })
    }

    /// The instruction-count table.
    pub fn text(&self) -> String {
        let mut t = String::from(
            "instructions per step on the emulated Cortex-M4 (QEMU TCG plugin; marker calls subtracted)\n",
        );
        t.push_str(&format!(
            "{:<22} {:>6} {:>10} {:>9} {:>9}\n",
            "what", "steps", "mean", "min", "max"
        ));
        for c in &self.counts {
            t.push_str(&format!(
                "{:<22} {:>6} {:>10.0} {:>9} {:>9}\n",
                c.label, c.n, c.mean, c.min, c.max
            ));
        }
        t.push_str("plant states after the counted steps, target vs host:");
        for (k, (name, _)) in PLANT_NUMBERS.iter().enumerate() {
            let exact = self.plant_states_equal(k);
            t.push_str(&format!(
                " {name} {}",
                if exact { "bit-identical" } else { "DIFFERENT" }
            ));
        }
        t.push('\n');
        t.push_str(&format!(
            "lockstep part: {} steps, actuator frames {} the native core's\n",
            self.lockstep.answers.len(),
            if self.answers_equal_native {
                "equal to"
            } else {
                "DIFFERENT from"
            }
        ));
        t
    }
}
