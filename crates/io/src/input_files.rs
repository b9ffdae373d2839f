//! The files a report was made from, each with its SHA-256: what an HTML report lists so that
//! a reader can tell which data it describes.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

/// A data file a report was made from, with its SHA-256 (hex) or why it has none.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct InputFile {
    /// The path as given.
    pub path: String,
    /// SHA-256 of its bytes, lower-case hex; or the reason it could not be read.
    pub sha256: std::result::Result<String, String>,
}

/// The files at `paths` with their hashes: a folder (a MUKCa placement) contributes each of its
/// files, sorted by name; a file that cannot be read is listed with the reason, a path that
/// does not exist (an optional sidecar) is left out.
pub fn input_files(paths: &[&Path]) -> Vec<InputFile> {
    let mut out = Vec::new();
    for path in paths.iter().filter(|p| p.exists()) {
        if path.is_dir() {
            let mut files: Vec<PathBuf> = std::fs::read_dir(path)
                .map(|d| {
                    d.flatten()
                        .map(|e| e.path())
                        .filter(|p| p.is_file())
                        .collect()
                })
                .unwrap_or_default();
            files.sort();
            for f in files {
                out.push(hashed(&f));
            }
        } else {
            out.push(hashed(path));
        }
    }
    out
}

/// One file and its SHA-256.
fn hashed(path: &Path) -> InputFile {
    InputFile {
        path: path.display().to_string(),
        sha256: std::fs::read(path)
            .map(|bytes| {
                let digest = Sha256::digest(&bytes);
                digest.iter().fold(String::new(), |mut s, b| {
                    let _ = write!(s, "{b:02x}");
                    s
                })
            })
            .map_err(|e| e.to_string()),
    }
}
