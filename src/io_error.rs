//! An I/O error that error enums deriving `Clone` and `PartialEq` (a file's parse errors, kept
//! in results that are compared and copied) can hold as their `#[source]`:
//! [`std::io::Error`] is neither, so it is shared behind an `Arc` and compared by kind and
//! message.

use std::sync::Arc;

/// A shared [`std::io::Error`].
#[derive(Debug, Clone)]
pub struct IoError(Arc<std::io::Error>);

impl IoError {
    /// The error's kind.
    pub fn kind(&self) -> std::io::ErrorKind {
        self.0.kind()
    }
}

impl From<std::io::Error> for IoError {
    fn from(e: std::io::Error) -> Self {
        IoError(Arc::new(e))
    }
}

impl PartialEq for IoError {
    fn eq(&self, other: &Self) -> bool {
        self.0.kind() == other.0.kind() && self.0.to_string() == other.0.to_string()
    }
}

impl std::fmt::Display for IoError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.fmt(f)
    }
}

impl std::error::Error for IoError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        self.0.source()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keeps_the_io_error_as_the_cause_and_compares_by_kind_and_message() {
        #[derive(Debug, Clone, PartialEq, thiserror::Error)]
        #[error("cannot read x.toml")]
        struct Outer(#[source] IoError);
        let e = Outer(std::fs::read("/nonexistent/x.toml").unwrap_err().into());
        assert_eq!(e.0.kind(), std::io::ErrorKind::NotFound);
        let chain = crate::error_chain::chain(&e);
        assert!(chain.starts_with("cannot read x.toml: "), "{chain}");
        assert!(chain.len() > "cannot read x.toml: ".len(), "{chain}");
        assert_eq!(e.clone(), e);
        assert_ne!(
            e,
            Outer(std::io::Error::from(std::io::ErrorKind::PermissionDenied).into())
        );
    }
}
