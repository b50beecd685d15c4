//! The workspace root: the nearest directory holding a `Cargo.toml` with a `[workspace]` table.

use std::path::{Path, PathBuf};

use crate::{Error, Result};

/// The nearest directory at or above `start` whose `Cargo.toml` has a `[workspace]` table.
pub fn find_workspace(start: &Path) -> Option<PathBuf> {
    start
        .ancestors()
        .find(|dir| {
            std::fs::read_to_string(dir.join("Cargo.toml"))
                .is_ok_and(|toml| toml.lines().any(|l| l.trim() == "[workspace]"))
        })
        .map(Path::to_path_buf)
}

/// The workspace holding the current directory (what the benchmarks use at run time, so they do
/// not depend on where the executable sits).
pub fn workspace_from_current_dir() -> Result<PathBuf> {
    let start = std::env::current_dir().map_err(Error::CurrentDir)?;
    find_workspace(&start).ok_or(Error::NoWorkspace { start })
}

/// The checkout this crate was built from (for tests, which always run inside it).
///
/// # Panics
/// When that checkout has no workspace `Cargo.toml` any more.
pub fn workspace_root() -> PathBuf {
    let manifest = Path::new(env!("CARGO_MANIFEST_DIR"));
    find_workspace(manifest).unwrap_or_else(|| {
        panic!(
            "{}",
            Error::NoWorkspace {
                start: manifest.to_path_buf()
            }
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_root_holds_the_members_and_a_member_is_not_a_root() {
        let root = workspace_root();
        assert!(
            root.join("testkit/Cargo.toml").is_file(),
            "{}",
            root.display()
        );
        assert_eq!(find_workspace(&root.join("testkit/src")), Some(root));
    }

    #[test]
    fn outside_any_workspace_there_is_none() {
        let dir = tempfile::tempdir().expect("a temporary directory");
        std::fs::write(dir.path().join("Cargo.toml"), "[package]\nname = \"x\"\n")
            .expect("a manifest");
        // A temporary directory sits outside the checkout, so only a stray workspace above
        // /tmp could be found.
        let found = find_workspace(dir.path());
        assert!(found.as_deref() != Some(dir.path()), "{found:?}");
    }
}
