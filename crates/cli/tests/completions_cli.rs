//! `dpctl completions`, `dpctl man` and `dpctl --version`.

use std::process::Command;

fn dpctl(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_dpctl"))
        .args(args)
        .output()
        .expect("run dpctl")
}

#[test]
fn completions_know_the_subcommands_and_their_options() {
    let out = dpctl(&["completions", "bash"]);
    assert!(out.status.success(), "{out:?}");
    let text = String::from_utf8(out.stdout).unwrap();
    for word in ["master", "slave", "sniff", "--port", "--config", "--pcap"] {
        assert!(text.contains(word), "bash completion without {word}");
    }
    let out = dpctl(&["completions", "zsh"]);
    assert!(
        out.status.success() && String::from_utf8_lossy(&out.stdout).contains("#compdef dpctl")
    );
    let out = dpctl(&["completions", "tcsh"]);
    assert_eq!(out.status.code(), Some(2), "unknown shell is a usage error");
}

#[test]
fn man_pages_describe_every_subcommand() {
    let out = dpctl(&["man"]);
    assert!(out.status.success(), "{out:?}");
    let page = String::from_utf8(out.stdout).unwrap();
    assert!(
        page.starts_with(".ie") || page.contains(".TH dpctl"),
        "{page}"
    );
    assert!(page.contains("master") && page.contains("sniff"));
    let dir = std::env::temp_dir().join(format!("dpctl-man-{}", std::process::id()));
    let out = dpctl(&["man", "--out-dir", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{out:?}");
    for page in [
        "dpctl.1",
        "dpctl-master.1",
        "dpctl-slave.1",
        "dpctl-sniff.1",
    ] {
        assert!(dir.join(page).is_file(), "{page} missing");
    }
    let master = std::fs::read_to_string(dir.join("dpctl-master.1")).unwrap();
    assert!(master.contains("config"), "{master}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn version_names_the_git_revision() {
    let out = dpctl(&["--version"]);
    assert!(out.status.success());
    let v = String::from_utf8(out.stdout).unwrap();
    assert!(
        v.starts_with(concat!("dpctl ", env!("CARGO_PKG_VERSION"), " (git ")),
        "{v}"
    );
    let rev = v.trim().trim_end_matches(')').rsplit(' ').next().unwrap();
    assert!(
        rev == "unknown" || (rev.len() >= 7 && rev.chars().all(|c| c.is_ascii_hexdigit())),
        "{v}"
    );
}
