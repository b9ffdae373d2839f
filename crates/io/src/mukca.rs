//! MUKCa real-robot recordings: `hole_0.csv`, `hole_1.csv`, … per tool placement.
//!
//! Layout (Franzese et al., "MUKCa", arXiv:2503.12584; `fixtures/mukca/README.md`): a
//! placement folder holds one file per socket, `hole_{k}.csv`, no header, one row per
//! configuration, one column per joint angle in rad. A run folder holds placement folders.

use std::path::{Path, PathBuf};

use crate::Error;
use crate::table::{Table, number};

/// One tool placement: the socket recordings of one folder.
#[derive(Clone, Debug, PartialEq)]
pub struct SocketPlacement {
    /// The folder's name (`front`, `left_back`, …).
    pub name: String,
    /// Socket `k` is `sockets[k]`, read from `hole_{k}.csv`.
    pub sockets: Vec<SocketSamples>,
}

/// The configurations recorded with the ball in one socket.
#[derive(Clone, Debug, PartialEq)]
pub struct SocketSamples {
    /// The file read.
    pub file: PathBuf,
    /// Joint angles, rad: `q[row][joint]`, rows × n_joints.
    pub q: Vec<Vec<f64>>,
    /// 1-based line of each row in `file`.
    pub line_numbers: Vec<u64>,
}

/// Reads the socket files `hole_0.csv` … `hole_k.csv` of one placement folder.
///
/// Each row must hold `n_joints` finite numbers. Joint limits are *not* checked: real
/// recordings may exceed a URDF's limits slightly.
///
/// # Errors
///
/// [`Error::Io`] if the folder or a file cannot be read; [`Error::NoSockets`] if there is
/// no `hole_*.csv`; [`Error::SocketGap`] if the numbers are not 0, 1, … without gaps;
/// [`Error::JointCount`] if the first row of a file does not have `n_joints` fields,
/// [`Error::Ragged`] if a later one does not; [`Error::NotANumber`], [`Error::NotFinite`]
/// for a bad cell (file:line:column, column = field number); [`Error::TooFewRows`] for a
/// file without rows; [`Error::Csv`] for invalid UTF-8.
pub fn read_mukca_placement(dir: &Path, n_joints: usize) -> Result<SocketPlacement, Error> {
    let mut numbers = socket_numbers(dir)?;
    if numbers.is_empty() {
        return Err(Error::NoSockets {
            dir: dir.to_path_buf(),
        });
    }
    numbers.sort_unstable();
    if let Some(missing) = (0..)
        .zip(&numbers)
        .find_map(|(k, n)| (k != *n).then_some(k))
    {
        return Err(Error::SocketGap {
            dir: dir.to_path_buf(),
            missing: format!("hole_{missing}.csv"),
        });
    }
    let sockets = numbers
        .iter()
        .map(|k| read_socket(&dir.join(format!("hole_{k}.csv")), n_joints))
        .collect::<Result<_, _>>()?;
    let name = dir.file_name().map_or_else(
        || dir.to_string_lossy().into_owned(),
        |n| n.to_string_lossy().into_owned(),
    );
    Ok(SocketPlacement { name, sockets })
}

/// Reads MUKCa placements from `paths`, each a placement folder (it holds `hole_*.csv`)
/// or a run folder whose subfolders holding `hole_*.csv` are placements, taken in name
/// order (other subfolders are skipped).
///
/// # Errors
///
/// As [`read_mukca_placement`]; [`Error::NoSockets`] for a run folder without any placement.
pub fn read_mukca_paths(paths: &[PathBuf], n_joints: usize) -> Result<Vec<SocketPlacement>, Error> {
    let mut placements = Vec::new();
    for path in paths {
        if !socket_numbers(path)?.is_empty() {
            placements.push(read_mukca_placement(path, n_joints)?);
            continue;
        }
        let mut subdirs = Vec::new();
        for entry in std::fs::read_dir(path).map_err(|e| Error::io(path, e))? {
            let entry = entry.map_err(|e| Error::io(path, e))?;
            let sub = entry.path();
            if sub.is_dir() && !socket_numbers(&sub)?.is_empty() {
                subdirs.push(sub);
            }
        }
        if subdirs.is_empty() {
            return Err(Error::NoSockets { dir: path.clone() });
        }
        subdirs.sort();
        for sub in subdirs {
            placements.push(read_mukca_placement(&sub, n_joints)?);
        }
    }
    Ok(placements)
}

/// The `k` of every `hole_{k}.csv` in `dir` (not `hole_0_pose.csv`), unsorted.
fn socket_numbers(dir: &Path) -> Result<Vec<usize>, Error> {
    let mut numbers = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
        let entry = entry.map_err(|e| Error::io(dir, e))?;
        let name = entry.file_name();
        let Some(digits) = name
            .to_str()
            .and_then(|n| n.strip_prefix("hole_"))
            .and_then(|n| n.strip_suffix(".csv"))
        else {
            continue;
        };
        let canonical = !digits.is_empty()
            && digits.bytes().all(|b| b.is_ascii_digit())
            && (digits == "0" || !digits.starts_with('0'));
        if let Some(k) = canonical.then(|| digits.parse().ok()).flatten() {
            numbers.push(k);
        }
    }
    Ok(numbers)
}

fn read_socket(path: &Path, n_joints: usize) -> Result<SocketSamples, Error> {
    let mut table = Table::open(path)?;
    let mut q = Vec::new();
    let mut line_numbers = Vec::new();
    while let Some((line, record)) = table.next_record()? {
        if record.len() != n_joints {
            return Err(if q.is_empty() {
                Error::JointCount {
                    path: path.to_path_buf(),
                    line,
                    expected: n_joints,
                    found: record.len(),
                }
            } else {
                Error::Ragged {
                    path: path.to_path_buf(),
                    line,
                    expected: n_joints,
                    found: record.len(),
                }
            });
        }
        let row = (record.iter().enumerate())
            .map(|(c, cell)| number(path, line, c as u64 + 1, &format!("q{}", c + 1), cell))
            .collect::<Result<Vec<f64>, _>>()?;
        q.push(row);
        line_numbers.push(line);
    }
    if q.is_empty() {
        return Err(Error::TooFewRows {
            path: path.to_path_buf(),
            min: 1,
            found: 0,
        });
    }
    Ok(SocketSamples {
        file: path.to_path_buf(),
        q,
        line_numbers,
    })
}
