//! The five-minute tour of docs/tour.md, run as written: its ```sh
//! blocks, in order, in one bash, as a user pasting them would. So the tour cannot
//! rot: a changed flag, output or file name fails this test.
//!
//! What differs from a user's shell, and why:
//! - `cargo install --path crates/cli` is left out: the `dpctl` cargo
//!   built for this test is first on PATH instead (the install itself is
//!   checked by `scripts/install-check`).
//! - `/tmp/` becomes a directory of this test, and the tour's MQTT port
//!   (`port=1883`, the block's first line) a free port, so that runs and
//!   other tests never share a link, a file or a broker.
//! - `set -e`: a command that fails ends the run (a pasted block would
//!   go on).
//!
//! The test asserts what the tour promises: the drive reaches
//! Data_Exchange and does 200 Data_Exchange cycles, the capture opens in
//! tshark with the dissector, the gateway's inputs show `"actual1":1500`,
//! and the tour leaves no process, link or broker behind. It fails when
//! mosquitto, tshark or bash is missing.

mod common;

use common::mqtt::{free_port, mosquitto};
use common::{dpctl, repo, require, Proc, TempDir};
use nix::sys::signal::{killpg, Signal};
use nix::unistd::Pid;
use std::process::Command;
use std::time::{Duration, Instant};

/// A process group, killed on drop: what the tour started and left
/// running (also when the test fails half-way).
struct Group(Pid);

impl Group {
    /// Whether a process of the group is still running.
    fn alive(&self) -> bool {
        killpg(self.0, None).is_ok()
    }
}

impl Drop for Group {
    fn drop(&mut self) {
        let _ = killpg(self.0, Signal::SIGKILL);
    }
}

/// The tour: the ```sh blocks of docs/tour.md, each as its text.
fn tour_blocks(page: &str) -> Vec<String> {
    let mut blocks = Vec::new();
    let mut block: Option<String> = None;
    for line in page.lines() {
        match (&mut block, line.trim_end()) {
            (None, "```sh") => block = Some(String::new()),
            (Some(b), "```") => {
                blocks.push(std::mem::take(b));
                block = None;
            }
            (Some(b), l) => {
                b.push_str(l);
                b.push('\n');
            }
            (None, _) => {}
        }
    }
    assert!(block.is_none(), "an unclosed ```sh block in the tour");
    blocks
}

/// The tour as one bash script for this test (see the module docs).
fn script(blocks: &[String], scratch: &str, port: u16) -> String {
    let mut s = String::from("set -e\n");
    let mut port_set = false;
    for b in blocks {
        for line in b.lines() {
            if line.starts_with("cargo install ") {
                continue;
            }
            if line == "port=1883" {
                port_set = true;
                s.push_str(&format!("port={port}\n"));
                continue;
            }
            s.push_str(&line.replace("/tmp/", &format!("{scratch}/")));
            s.push('\n');
        }
    }
    assert!(port_set, "the tour sets its MQTT port with `port=1883`");
    s
}

#[test]
fn tour_blocks_are_the_pages_sh_blocks() {
    let page = "# A five-minute tour\ntext with ```sh inline\n```sh\na\nb\n```\n\
                ```text\nno\n```\n## Next\n```sh\nc\n```\n";
    assert_eq!(tour_blocks(page), ["a\nb\n", "c\n"]);
}

#[test]
fn the_tour_runs_as_written() {
    for tool in ["bash", "tshark", "mosquitto_sub", "mosquitto_pub"] {
        require(tool);
    }
    let page = std::fs::read_to_string(repo().join("docs/tour.md")).unwrap();
    let blocks = tour_blocks(&page);
    assert!(blocks.len() >= 5, "the tour's blocks: {blocks:?}");
    let dir = TempDir::new("tour");
    let scratch = dir.0.to_str().unwrap().to_string();
    let text = script(&blocks, &scratch, free_port());
    let file = dir.path("tour.sh");
    std::fs::write(&file, &text).unwrap();

    // dpctl from this build, and mosquitto (Debian: /usr/sbin), first.
    let bin = |p: &std::path::Path| p.parent().unwrap().to_path_buf();
    let path = std::env::var_os("PATH").unwrap_or_default();
    let dirs = [bin(&dpctl()), bin(&mosquitto())];
    let path = std::env::join_paths(dirs.into_iter().chain(std::env::split_paths(&path))).unwrap();
    let mut cmd = Command::new("bash");
    cmd.arg(&file)
        .current_dir(repo())
        .env("PATH", path)
        .env_remove("DPCTL_LOG");
    // Its own process group: whatever the tour leaves running is found
    // (and stopped) by the group.
    std::os::unix::process::CommandExt::process_group(&mut cmd, 0);
    let mut tour = Proc::spawn_captured(cmd);
    let group = Group(Pid::from_raw(tour.pid() as i32));
    // A hang guard, generous for a loaded machine; the tour itself waits
    // on events only.
    let end = Instant::now() + Duration::from_secs(600);
    while !tour.exited() && Instant::now() < end {
        std::thread::sleep(Duration::from_millis(50));
    }
    let hung = !tour.exited();
    if hung {
        let _ = killpg(group.0, Signal::SIGKILL);
    }
    let out = tour.finish(Duration::from_secs(30));
    let left = group.alive();
    drop(group);
    let all = format!(
        "script:\n{text}\nstdout:\n{}\nstderr:\n{}",
        out.stdout, out.stderr
    );
    assert!(!hung, "the tour hung (killed after 600 s)\n{all}");
    assert!(
        out.status.success(),
        "the tour failed: {:?}\n{all}",
        out.status
    );
    assert!(!left, "the tour left processes running\n{all}");
    for l in out.stderr.lines() {
        assert!(!l.starts_with("dpctl: "), "a command failed: {l}\n{all}");
    }

    // Step 4: the drive in Data_Exchange, 200 cycles (the slave's own
    // count, printed when it stops).
    let o = &out.stdout;
    assert!(
        o.contains("slave 25: check_diag → data_exchange"),
        "the drive did not reach Data_Exchange\n{all}"
    );
    let cycles: u64 = o
        .lines()
        .find_map(|l| {
            let rest = l.split("stopped in Data_Exch: ").nth(1)?;
            rest.split(' ').next()?.parse().ok()
        })
        .unwrap_or_else(|| panic!("the drive's closing line is missing\n{all}"));
    assert!(cycles >= 200, "{cycles} Data_Exchange cycles\n{all}");
    // Step 5: the dissector decodes the capture's DP layer.
    assert!(
        o.lines()
            .any(|l| l.contains("PROFIBUS DP") && l.contains("Data_Exchange")),
        "tshark did not decode the capture\n{all}"
    );
    assert!(!o.contains("Lua Error"), "the dissector failed\n{all}");
    // Step 6: the drive follows the setpoint written over MQTT.
    assert!(
        o.contains("\"actual1\":1500"),
        "no \"actual1\":1500 in the gateway's inputs\n{all}"
    );
    // The bus removed its links; the listeners wrote their files.
    for i in 0..4 {
        let link = dir.path(&format!("pb{i}"));
        assert!(std::fs::symlink_metadata(&link).is_err(), "{link:?} left");
    }
    assert!(dir.path("tour-sniff.txt").exists());
}
