//! Helpers shared by the integration tests that read the library's own sources (the
//! architecture checks: the diagnosis does not use the truth generator, the DBC is the only
//! source of ids and signal positions, the model never renders).

use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir`, recursively, sorted.
pub fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            out.extend(rust_files(&p));
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
    out.sort();
    out
}

/// `src/<sub>` of this crate.
pub fn src(sub: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src").join(sub)
}

/// Asserts that no `.rs` file under `src/<dir>` for each of `dirs` contains any of `needles`
/// (the failure names the file, the needle and `what` it means); returns the files checked.
#[allow(dead_code)] // not every test binary that includes this module runs a source check
pub fn assert_sources_lack(dirs: &[&str], needles: &[&str], what: &str) -> usize {
    let mut checked = 0;
    for dir in dirs {
        for p in rust_files(&src(dir)) {
            let text = std::fs::read_to_string(&p).unwrap();
            for needle in needles {
                assert!(
                    !text.contains(needle),
                    "{} {what} (`{needle}`)",
                    p.display()
                );
            }
            checked += 1;
        }
    }
    checked
}
