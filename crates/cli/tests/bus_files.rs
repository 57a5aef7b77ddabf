//! Bus files and names end to end: every bus file README.md and docs/
//! show is taken by every command with `--config`; a name that is not
//! valid (a module, a key, a device, an option) stops `dpctl` with one
//! line that says where and names the closest valid names.

mod common;

use common::*;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `dpctl ARGS` run in `dir`: exit status and stderr.
fn dpctl_in(dir: &Path, args: &[&str]) -> (std::process::ExitStatus, String) {
    let out = Command::new(dpctl())
        .args(args)
        .current_dir(dir)
        .env_remove("DPCTL_LOG")
        .output()
        .unwrap();
    (
        out.status,
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// A directory where the repository's relative paths (crates/…)
/// resolve as from the repository's root, as the docs' commands run.
/// The built-in GSD files are there too: a doc that copies one next to
/// its bus file (`cp crates/devices/gsd/DPCTL_GEN.GSD /tmp/gw/`, before
/// the here-document) names it without a directory, and a bus file that
/// `dpctl scan --write-config` wrote names it in `gsd/`, where the scan
/// copies the built-in files it used (docs/commissioning.md).
fn workdir() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(repo().join("crates"), dir.path().join("crates")).unwrap();
    std::fs::create_dir(dir.path().join("gsd")).unwrap();
    for e in std::fs::read_dir(repo().join("crates/devices/gsd")).unwrap() {
        let p = e.unwrap().path();
        if profibus::dp::config::gsd::is_gsd_file_name(&p) {
            let name = p.file_name().unwrap();
            std::os::unix::fs::symlink(&p, dir.path().join(name)).unwrap();
            std::os::unix::fs::symlink(&p, dir.path().join("gsd").join(name)).unwrap();
        }
    }
    dir
}

/// The bus files of a Markdown text: the here-documents of shell blocks
/// (`cat > FILE <<'END'` … `END`) and the ```toml blocks that are bus
/// files or parts of one (a `[master]` or `[[slave]]` table; a block
/// with slaves only is completed with a `[master]` table), with the
/// line each starts at. In a here-document whose delimiter is not
/// quoted the shell expands `$PWD`: it stays in the text, marked by
/// [`EXPAND_PWD`] before it, for the caller to expand.
fn bus_files(md: &str) -> Vec<(usize, String)> {
    let lines: Vec<&str> = md.lines().collect();
    let mut out = vec![];
    let mut i = 0;
    while i < lines.len() {
        let l = lines[i].trim();
        let end = if l == "```toml" {
            Some("```".to_string())
        } else {
            l.split_once("<<")
                .filter(|_| l.starts_with("cat >"))
                .map(|(_, m)| m.trim().trim_matches(['\'', '"']).to_string())
        };
        if let Some(end) = end {
            let start = i + 1;
            let mut body = vec![];
            i += 1;
            while i < lines.len() && lines[i].trim() != end {
                body.push(lines[i]);
                i += 1;
            }
            let mut text = body.join("\n") + "\n";
            let unquoted = l.starts_with("cat >") && !l.contains(['\'', '"']);
            if unquoted && text.contains("$PWD") {
                text = format!("{EXPAND_PWD}{text}");
            }
            let has = |t: &str| body.iter().any(|l| l.trim() == t);
            if has("[master]") {
                out.push((start, text));
            } else if has("[[slave]]") {
                out.push((
                    start,
                    format!("[master]\naddress = 2\nbaud = \"1.5M\"\n\n{text}"),
                ));
            }
        }
        i += 1;
    }
    out
}

/// First line of a bus file whose `$PWD` the shell expands (a
/// here-document with an unquoted delimiter): a TOML comment.
const EXPAND_PWD: &str = "# $PWD expanded\n";

/// The first slave address of a bus file.
fn first_slave(text: &str) -> String {
    let t: toml::Table = text.parse().unwrap();
    t["slave"].as_array().unwrap()[0]["address"]
        .as_integer()
        .unwrap()
        .to_string()
}

/// Every command that takes `--config`, with the bus file `bus` and a
/// port that is no serial line (so that each stops after loading it).
fn commands(bus: &str, slave: &str) -> Vec<Vec<String>> {
    let port = "/dev/null";
    [
        vec!["master", "--port", port, "--config", bus, "--plain"],
        vec!["monitor", "--port", port, "--config", bus, "--plain"],
        vec!["doctor", "--port", port, "--config", bus],
        vec![
            "dpv1", "--port", port, "--config", bus, "--slave", slave, "read",
        ],
        vec![
            "pkw", "--port", port, "--config", bus, "--slave", slave, "read", "1",
        ],
        vec![
            "rfid", "--port", port, "--config", bus, "--slave", slave, "VER",
        ],
        vec![
            "gateway",
            "--port",
            port,
            "--config",
            bus,
            "--mqtt",
            "mqtt://127.0.0.1:1",
        ],
    ]
    .into_iter()
    .map(|c| c.into_iter().map(String::from).collect())
    .collect()
}

#[test]
fn every_command_with_config_takes_every_bus_file_of_the_docs() {
    let mut docs: Vec<PathBuf> = vec![repo().join("README.md")];
    let mut dirs = vec![repo().join("docs")];
    while let Some(d) = dirs.pop() {
        for e in std::fs::read_dir(d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                docs.push(p);
            }
        }
    }
    let dir = workdir();
    let mut checked = 0;
    for doc in &docs {
        let md = std::fs::read_to_string(doc).unwrap();
        for (line, text) in bus_files(&md) {
            let name = format!("bus-{checked}.toml");
            let text = match text.strip_prefix(EXPAND_PWD) {
                // The commands run in `dir`, as from the repository's root.
                Some(t) => t.replace("$PWD", &dir.path().display().to_string()),
                None => text,
            };
            std::fs::write(dir.path().join(&name), &text).unwrap();
            let slave = first_slave(&text);
            for args in commands(&name, &slave) {
                let args: Vec<&str> = args.iter().map(String::as_str).collect();
                let (status, err) = dpctl_in(dir.path(), &args);
                // Loaded: the command fails at the port (or later), never
                // at the bus file, whose errors start with its name and a
                // place (`bus-0.toml:3:1: …`; start-up log lines name the
                // file without one).
                assert!(
                    !status.success() && !err.contains(&format!("{name}:")),
                    "{}:{line}: dpctl {}: {err}\n{text}",
                    doc.display(),
                    args.join(" ")
                );
            }
            checked += 1;
        }
    }
    assert!(checked >= 4, "only {checked} bus files found");
}

/// A bus file of master 2 and one slave (the `[[slave]]` lines given).
fn bus_with(dir: &Path, slave: &str) -> String {
    let text = format!("[master]\naddress = 2\nbaud = \"1.5M\"\n\n[[slave]]\n{slave}");
    std::fs::write(dir.join("bad.toml"), text).unwrap();
    "bad.toml".into()
}

#[test]
fn a_wrong_name_is_one_line_with_its_place_and_the_closest_names() {
    let dir = workdir();
    let d = dir.path();
    for (slave, want) in [
        (
            "address = 5\ngsd = \"crates/devices/gsd/DPCTL_GEN.GSD\"\nmodules = [\"3 words in/out\"]\n",
            "dpctl: bad.toml:8:12: slave 5: crates/devices/gsd/DPCTL_GEN.GSD: no module named \
             `3 words in/out`; did you mean `2 words in/out`?",
        ),
        (
            "adress = 5\ndevice = \"omega\"\n",
            "dpctl: bad.toml:6:1: unknown key `adress` in [[slave]]; did you mean `address`?",
        ),
        (
            "address = 5\ndevice = \"omgea\"\n",
            "dpctl: bad.toml:7:10: slave 5: no device profile `omgea`; did you mean `omega`? \
             (available: generic, bm4, omega, jx2, rfid, bk3000)",
        ),
        (
            "address = 5\ndevice = \"omega\"\nsetpoint = 2\n",
            "dpctl: bad.toml:8:1: slave 5: device `omega`: unknown option `setpoint`; \
             did you mean `setpoints`?",
        ),
        (
            "address = 5\ndevice = \"omega\"\nsetpoints = \"x\"\n",
            "dpctl: bad.toml:8:1: slave 5: device `omega`: option `setpoints`: `x` is not a number",
        ),
        (
            "address = 5\ndevice = \"bk3000\"\nterminals = [\"KL1104\", \"KL2135\", \"KL9010\"]\n",
            "dpctl: bad.toml:8:1: slave 5: device `bk3000`: option `terminals`: terminal 2: \
             `KL2135` is not in the catalogue; did you mean `KL2134`?",
        ),
    ] {
        let bus = bus_with(d, slave);
        let (status, err) = dpctl_in(d, &["master", "--port", "/dev/null", "--config", &bus]);
        assert_eq!(status.code(), Some(1), "{err}");
        assert_eq!(err.trim_end(), want, "{slave}");
    }
    // The same names on the command line of `dpctl slave`.
    for (args, want) in [
        (
            &[
                "--gsd",
                "crates/devices/gsd/DPCTL_GEN.GSD",
                "--module",
                "3 words in/out",
            ][..],
            "no module named `3 words in/out`; did you mean `2 words in/out`?",
        ),
        (
            &["--device", "omega", "--device-opt", "setpoint=2"][..],
            "dpctl: device `omega`: unknown option `setpoint`; did you mean `setpoints`?",
        ),
        (
            &["--device", "omgea"][..],
            "dpctl: no device profile `omgea`; did you mean `omega`?",
        ),
    ] {
        let mut all = vec!["slave", "--port", "/dev/null", "--addr", "5"];
        all.extend_from_slice(args);
        let (status, err) = dpctl_in(d, &all);
        assert_eq!(status.code(), Some(1), "{err}");
        assert_eq!(err.lines().count(), 1, "one line: {err}");
        assert!(err.contains(want), "{args:?}: {err}");
    }
}
