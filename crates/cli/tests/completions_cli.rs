//! `dpctl completions`, `dpctl man` and `dpctl --version`.

mod common;

use common::{run_dpctl as dpctl, TempDir};

#[test]
fn completions_know_the_subcommands_and_their_options() {
    let out = dpctl(&["completions", "bash"]);
    assert!(out.status.success(), "{out:?}");
    let text = out.stdout;
    for word in ["master", "slave", "sniff", "--port", "--config", "--pcap"] {
        assert!(text.contains(word), "bash completion without {word}");
    }
    let out = dpctl(&["completions", "zsh"]);
    assert!(out.status.success() && out.stdout.contains("#compdef dpctl"));
    let out = dpctl(&["completions", "tcsh"]);
    assert_eq!(out.status.code(), Some(2), "unknown shell is a usage error");
}

#[test]
fn man_pages_describe_every_subcommand() {
    let out = dpctl(&["man"]);
    assert!(out.status.success(), "{out:?}");
    let page = out.stdout;
    assert!(
        page.starts_with(".ie") || page.contains(".TH dpctl"),
        "{page}"
    );
    assert!(page.contains("master") && page.contains("sniff"));
    let tmp = TempDir::new("man");
    let dir = &tmp.0;
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
}

#[test]
fn version_names_the_git_revision() {
    let out = dpctl(&["--version"]);
    assert!(out.status.success());
    let v = out.stdout;
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
