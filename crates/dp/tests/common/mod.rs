//! What the GSD file tests share: where the repository's GSD files are.

use std::path::{Path, PathBuf};

/// The repository root (absolute, no `..`).
pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .unwrap()
}

/// Every `.gsd` file in `crates/devices/gsd/` and `crates/devices/gsd/corpus/`, sorted.
pub fn gsd_files() -> Vec<PathBuf> {
    let mut v = Vec::new();
    for dir in ["crates/devices/gsd", "crates/devices/gsd/corpus"] {
        for e in std::fs::read_dir(root().join(dir)).unwrap() {
            let p = e.unwrap().path();
            if profibus_dp::config::gsd::is_gsd_file_name(&p) {
                v.push(p);
            }
        }
    }
    v.sort();
    assert!(
        v.len() >= 15,
        "expected the device files and the corpus, found {v:?}"
    );
    v
}
