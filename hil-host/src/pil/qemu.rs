//! The emulated board: where the firmware image and QEMU's instruction-counting plugin are
//! found (at run time, never baked in), how the image is built, and a running QEMU with its
//! serial port connected, killed on every path when dropped.

use std::fs::File;
use std::net::{Ipv4Addr, SocketAddr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// The firmware's target triple and package.
pub const TARGET: &str = "thumbv7em-none-eabihf";
pub const FIRMWARE_PACKAGE: &str = "firmware-qemu";
/// The QEMU binary and machine.
pub const QEMU: &str = "qemu-system-arm";
pub const MACHINE: &str = "netduinoplus2";

/// Whether `dir` is this project's workspace root: a Cargo.toml with a `[workspace]` table and
/// the firmware-qemu package beside it.
fn is_workspace_root(dir: &Path) -> bool {
    dir.join(FIRMWARE_PACKAGE).join("Cargo.toml").is_file()
        && std::fs::read_to_string(dir.join("Cargo.toml")).is_ok_and(|t| t.lines().any(|l| l.trim() == "[workspace]"))
}

/// The workspace root, found at run time (never baked in at compile time): the nearest
/// ancestor of the current directory that is this project's workspace, else the nearest of the
/// running binary's location (`target/release/hil-host` lies inside it). `None` outside a
/// checkout, as for a hil-host copied elsewhere.
pub fn workspace_root() -> Option<PathBuf> {
    let from_cwd = std::env::current_dir().ok();
    let from_exe = std::env::current_exe().ok().and_then(|e| e.canonicalize().ok());
    [from_cwd, from_exe]
        .into_iter()
        .flatten()
        .find_map(|start| start.ancestors().find(|d| is_workspace_root(d)).map(Path::to_path_buf))
}

/// Cargo's target directory of the workspace at `root`: `CARGO_TARGET_DIR` when set (relative
/// to `root`, where [`build_firmware`] runs cargo), else `<root>/target`.
pub fn target_dir(root: &Path) -> PathBuf {
    match std::env::var_os("CARGO_TARGET_DIR") {
        Some(d) => root.join(d),
        None => root.join("target"),
    }
}

/// The cargo profile the firmware images are built with (size-optimised, fat LTO; the
/// workspace's `[profile.firmware]`).
pub const FIRMWARE_PROFILE: &str = "firmware";

/// Where `cargo build --profile firmware -p firmware-qemu --target thumbv7em-none-eabihf` puts
/// the ELF in the workspace at `root`.
pub fn firmware_elf_path(root: &Path) -> PathBuf {
    target_dir(root)
        .join(TARGET)
        .join(FIRMWARE_PROFILE)
        .join(FIRMWARE_PACKAGE)
}

/// The firmware image for `pil` and `target-bench`, looked up at run time: `elf` when given
/// (`--elf`); else `firmware-qemu` next to the running hil-host binary (an installed pair);
/// else the workspace's image (found by [`workspace_root`]), built by [`build_firmware`] so it
/// is current. The error names every place looked at.
pub fn find_firmware(elf: Option<&Path>) -> Result<PathBuf, String> {
    if let Some(e) = elf {
        return if e.is_file() {
            Ok(e.to_path_buf())
        } else {
            Err(format!("--elf {}: no such firmware image", e.display()))
        };
    }
    let beside = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(|d| d.join(FIRMWARE_PACKAGE)));
    if let Some(b) = beside.as_ref().filter(|b| b.is_file()) {
        return Ok(b.clone());
    }
    if workspace_root().is_some() {
        return build_firmware();
    }
    Err(format!(
        "no firmware image: pass --elf, put {FIRMWARE_PACKAGE} next to hil-host ({}), or run inside the project's workspace (neither the current directory nor the binary's location is in one)",
        beside.map_or_else(|| "location unknown".into(), |b| b.display().to_string())
    ))
}

/// Builds the firmware image (profile `firmware`, locked, the workspace's target directory) and returns
/// its path. Must not be called while cargo holds the build lock of the same target
/// directory (from a build script, say); a running test binary is fine.
pub fn build_firmware() -> Result<PathBuf, String> {
    let root = workspace_root().ok_or_else(|| {
        format!("cannot build {FIRMWARE_PACKAGE}: neither the current directory nor the binary's location is inside the project's workspace")
    })?;
    let cargo = std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into());
    let status = Command::new(cargo)
        .current_dir(&root)
        .args([
            "build",
            "--profile",
            FIRMWARE_PROFILE,
            "--locked",
            "-p",
            FIRMWARE_PACKAGE,
            "--target",
            TARGET,
        ])
        .status()
        .map_err(|e| format!("cannot run cargo to build {FIRMWARE_PACKAGE}: {e}"))?;
    if !status.success() {
        return Err(format!("building {FIRMWARE_PACKAGE} failed ({status})"));
    }
    let elf = firmware_elf_path(&root);
    if elf.is_file() {
        Ok(elf)
    } else {
        Err(format!(
            "cargo built {FIRMWARE_PACKAGE} but {} is missing",
            elf.display()
        ))
    }
}

/// `qemu-system-arm --version`'s first line, or why it cannot be run.
pub fn qemu_version() -> Result<String, String> {
    let out = Command::new(QEMU)
        .arg("--version")
        .output()
        .map_err(|e| format!("{QEMU} not found ({e}); run tools/setup-qemu.sh"))?;
    let text = String::from_utf8_lossy(&out.stdout);
    Ok(text.lines().next().unwrap_or("").to_string())
}

/// The instruction-counting TCG plugin's file name.
pub const PLUGIN: &str = "insn_between.so";

/// The instruction-counting TCG plugin (built by tools/setup-qemu.sh), found at run time: next
/// to the running hil-host binary, else in the workspace's `tools/qemu-plugin/`.
pub fn plugin_path() -> Result<PathBuf, String> {
    let beside = std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(|d| d.join(PLUGIN)));
    if let Some(b) = beside.filter(|b| b.is_file()) {
        return Ok(b);
    }
    workspace_root()
        .map(|r| r.join("tools/qemu-plugin").join(PLUGIN))
        .ok_or_else(|| {
            format!("{PLUGIN}: not next to hil-host and no workspace found; run tools/setup-qemu.sh in the project")
        })
}

/// How QEMU is started.
#[derive(Clone, Debug, Default)]
pub struct QemuOptions {
    /// Semihosting arguments after the program name (`bench` selects the bench mode).
    pub args: Vec<String>,
    /// `-plugin` argument (`path,key=value,...`).
    pub plugin: Option<String>,
    /// A calibration image QEMU writes into the calibration sector's flash before the
    /// firmware starts (`-device loader`, at [`crate::calibrate::FLASH_BASE`]).
    pub calibration: Option<PathBuf>,
    /// Where QEMU's stdout (the defmt stream over semihosting) and stderr go; a temporary
    /// directory's files when `None`.
    pub log_dir: Option<PathBuf>,
}

/// A running QEMU with the firmware and the TCP connection to its USART1. Dropping it kills
/// QEMU.
pub struct QemuBoard {
    child: Child,
    pub(super) stream: TcpStream,
    /// QEMU's stdout: the firmware's defmt frames (decode with `defmt-print -e <elf>`), in
    /// place once the board is dropped (QEMU streams into a temporary file until then).
    pub defmt_log: PathBuf,
    /// Where QEMU streams while it runs: stdout, stderr.
    live: [PathBuf; 2],
    /// QEMU's stderr, in place once the board is dropped.
    stderr_log: PathBuf,
}

impl Drop for QemuBoard {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        // Whole streams only under their final names: a killed host leaves the previous run's
        // files (or none) and the temporaries.
        let _ = std::fs::rename(&self.live[0], &self.defmt_log);
        let _ = std::fs::rename(&self.live[1], &self.stderr_log);
    }
}

/// The temporary name QEMU streams `file` into while it runs.
pub(super) fn live_name(file: &Path) -> PathBuf {
    let name = file
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    file.with_file_name(format!("{}{name}", crate::output::TMP_PREFIX))
}

impl QemuBoard {
    /// Starts QEMU with `elf` on a free local port and connects to its serial port.
    pub fn start(elf: &Path, opts: &QemuOptions) -> Result<Self, String> {
        if !elf.is_file() {
            return Err(format!("{}: no such firmware image", elf.display()));
        }
        let dir = match &opts.log_dir {
            Some(d) => d.clone(),
            None => std::env::temp_dir().join(format!("hil-pil-{}", std::process::id())),
        };
        std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let defmt_log = dir.join("defmt.bin");
        let stderr_log = dir.join("qemu-stderr.txt");
        for f in [&defmt_log, &stderr_log] {
            crate::output::check_not_input(f).map_err(|e| e.to_string())?;
        }
        let live = [live_name(&defmt_log), live_name(&stderr_log)];
        // A port that was free a moment ago; QEMU failing to bind it (a race with another
        // process) is retried on a new one.
        let mut last_err = String::new();
        for _ in 0..3 {
            let port = free_port()?;
            let mut semihosting = String::from("enable=on,target=native,arg=firmware-qemu");
            for a in &opts.args {
                semihosting.push_str(",arg=");
                semihosting.push_str(a);
            }
            let mut cmd = Command::new(QEMU);
            cmd.args(["-M", MACHINE, "-display", "none", "-monitor", "none"])
                .args(["-semihosting-config", &semihosting])
                .args(["-serial", &format!("tcp:127.0.0.1:{port},server=on,wait=on,nodelay=on")])
                .arg("-kernel")
                .arg(elf);
            if let Some(p) = &opts.plugin {
                cmd.args(["-plugin", p]);
            }
            if let Some(c) = &opts.calibration {
                cmd.arg("-device").arg(format!(
                    "loader,file={},addr=0x{:08X},force-raw=on",
                    c.display(),
                    crate::calibrate::FLASH_BASE
                ));
            }
            let out = File::create(&live[0]).map_err(|e| format!("{}: {e}", live[0].display()))?;
            let err = File::create(&live[1]).map_err(|e| format!("{}: {e}", live[1].display()))?;
            let child = cmd
                .stdin(Stdio::null())
                .stdout(out)
                .stderr(err)
                .spawn()
                .map_err(|e| format!("cannot start {QEMU} ({e}); run tools/setup-qemu.sh"))?;
            let mut board = Pending { child: Some(child) };
            match connect(&mut board, port, &live[1]) {
                Ok(stream) => {
                    let child = board.child.take().ok_or("QEMU process lost")?;
                    return Ok(QemuBoard {
                        child,
                        stream,
                        defmt_log,
                        live,
                        stderr_log,
                    });
                }
                Err(e) => last_err = e,
            }
        }
        // QEMU's last words stay readable under the usual name.
        let _ = std::fs::remove_file(&live[0]);
        let _ = std::fs::rename(&live[1], &stderr_log);
        Err(last_err)
    }

    /// What QEMU printed on stderr so far.
    pub fn stderr_text(&self) -> String {
        std::fs::read_to_string(&self.live[1]).unwrap_or_default()
    }

    /// Whether QEMU is still running.
    pub fn running(&mut self) -> bool {
        matches!(self.child.try_wait(), Ok(None))
    }

    pub fn stream(&mut self) -> &mut TcpStream {
        &mut self.stream
    }
}

/// A QEMU child not yet connected: killed on drop too.
pub(super) struct Pending {
    child: Option<Child>,
}

impl Drop for Pending {
    fn drop(&mut self) {
        if let Some(c) = self.child.as_mut() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

pub(super) fn free_port() -> Result<u16, String> {
    let l = TcpListener::bind((Ipv4Addr::LOCALHOST, 0)).map_err(|e| format!("no free local port: {e}"))?;
    l.local_addr().map(|a| a.port()).map_err(|e| e.to_string())
}

pub(super) fn connect(board: &mut Pending, port: u16, stderr_log: &Path) -> Result<TcpStream, String> {
    let addr = SocketAddr::from((Ipv4Addr::LOCALHOST, port));
    let start = Instant::now();
    loop {
        if let Some(c) = board.child.as_mut() {
            if let Ok(Some(status)) = c.try_wait() {
                let text = std::fs::read_to_string(stderr_log).unwrap_or_default();
                return Err(format!(
                    "{QEMU} exited ({status}) before accepting the serial connection: {}",
                    text.trim()
                ));
            }
        }
        match TcpStream::connect_timeout(&addr, Duration::from_millis(200)) {
            Ok(s) => {
                // Without it every small frame waits for the previous one's ACK (~40 ms).
                s.set_nodelay(true).map_err(|e| format!("TCP_NODELAY: {e}"))?;
                return Ok(s);
            }
            Err(_) if start.elapsed() < Duration::from_secs(20) => std::thread::sleep(Duration::from_millis(20)),
            Err(e) => return Err(format!("cannot connect to {QEMU}'s serial port {port}: {e}")),
        }
    }
}
