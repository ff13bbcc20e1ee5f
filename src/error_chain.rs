//! An error with its causes on one line, `outer: cause: root` — what `anyhow`'s `{:#}` prints,
//! for library code and tests that hold a typed error. The module errors do not repeat their
//! source in their own message (`#[source]` carries it), so this is how the whole is read.

use std::error::Error;

/// `e` and each of its sources, joined by `: `.
pub fn chain(e: &dyn Error) -> String {
    let mut s = e.to_string();
    let mut cur = e.source();
    while let Some(c) = cur {
        s.push_str(": ");
        s.push_str(&c.to_string());
        cur = c.source();
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug, thiserror::Error)]
    #[error("outer")]
    struct Outer(#[source] std::io::Error);

    #[test]
    fn joins_the_causes() {
        let e = Outer(std::io::Error::other("root"));
        assert_eq!(chain(&e), "outer: root");
        assert_eq!(
            format!(
                "{:#}",
                anyhow::Error::new(Outer(std::io::Error::other("root")))
            ),
            chain(&e)
        );
    }
}
