//! The library's one error type. Modules with errors a caller branches on
//! keep their own thiserror enums (`DataError`, `ModelFileError`, ...), made
//! into this type by `typed_errors!` in their own module (so that this
//! module imports none of them) and found again with [`Error::find`]. It also
//! carries the errors of the crates underneath (I/O, JSON, candle) and the
//! context each step adds. The binary turns it into `anyhow` at its edge.

use std::fmt::Display;

/// A module's typed error, boxed.
pub type BoxedError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// A failure of a library call, with what was being done when it happened.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Reading or writing a file or socket.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// JSON that does not parse or encode.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// A tensor operation of the candle models.
    #[error(transparent)]
    Candle(#[from] candle_core::Error),
    /// A module's own error (a bag, a model file, a physics setting, ...).
    #[error(transparent)]
    Typed(BoxedError),
    /// An input or state the call refuses; the message names the fix.
    #[error("{0}")]
    Msg(String),
    /// What was being done, and why it failed. The message carries the whole
    /// chain ("context: cause"), as the CLI, the node's replies and the
    /// reproduce report show it, so the cause is not also a `source()`.
    #[error("{context}: {inner}")]
    Context {
        /// The step that failed.
        context: String,
        /// Why it failed.
        inner: Box<Error>,
    },
}

/// A library result.
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// An error with just a message.
    pub fn msg(m: impl Display) -> Self {
        Error::Msg(m.to_string())
    }

    /// The module error of type `T` at the root of this error, if it is one
    /// (looking through the context).
    pub fn find<T: std::error::Error + 'static>(&self) -> Option<&T> {
        match self {
            Error::Typed(e) => e.downcast_ref(),
            Error::Context { inner, .. } => inner.find(),
            _ => None,
        }
    }
}

/// `From` each listed error type into [`Error::Typed`], so that `?` takes it.
macro_rules! typed_errors {
    ($($t:ty),+ $(,)?) => {
        $(impl From<$t> for $crate::error::Error {
            fn from(e: $t) -> Self {
                $crate::error::Error::Typed(Box::new(e))
            }
        })+
    };
}

typed_errors!(rand_distr::NormalError, rayon::ThreadPoolBuildError);

/// Adds what was being done to an error, as `crate::error::Context` does.
pub trait Context<T> {
    /// Wraps the error with `context`.
    fn context<C: Display>(self, context: C) -> Result<T>;
    /// Wraps the error with the context `f` makes (only on failure).
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T>;
}

impl<T, E: Into<Error>> Context<T> for std::result::Result<T, E> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.map_err(|e| Error::Context {
            context: context.to_string(),
            inner: Box::new(e.into()),
        })
    }

    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.map_err(|e| Error::Context {
            context: f().to_string(),
            inner: Box::new(e.into()),
        })
    }
}

impl<T> Context<T> for Option<T> {
    fn context<C: Display>(self, context: C) -> Result<T> {
        self.ok_or_else(|| Error::msg(context))
    }

    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T> {
        self.ok_or_else(|| Error::msg(f()))
    }
}

/// An [`Error::Msg`] from a format string.
macro_rules! err {
    ($($t:tt)*) => {
        $crate::error::Error::Msg(format!($($t)*))
    };
}

/// Returns an [`Error::Msg`] from a format string.
macro_rules! bail {
    ($($t:tt)*) => {
        return Err($crate::error::err!($($t)*).into())
    };
}

pub(crate) use {bail, err, typed_errors};

#[cfg(test)]
mod tests {
    use super::*;

    fn refuse(x: i32) -> Result<i32> {
        if x <= 0 {
            bail!("x must be positive, got {x}");
        }
        Ok(x)
    }

    #[test]
    fn context_chains_read_outside_in() {
        let e = refuse(-1).context("reading the model").unwrap_err();
        assert_eq!(
            e.to_string(),
            "reading the model: x must be positive, got -1"
        );
        let io: std::result::Result<(), std::io::Error> =
            Err(std::io::Error::new(std::io::ErrorKind::NotFound, "gone"));
        let e = io.with_context(|| "opening a.mcap").unwrap_err();
        assert!(matches!(&e, Error::Context { inner, .. } if matches!(**inner, Error::Io(_))));
        assert_eq!(format!("{e:#}"), "opening a.mcap: gone");
        assert_eq!(refuse(2).unwrap(), 2);
        assert_eq!(
            None::<u8>.context("no state").unwrap_err().to_string(),
            "no state"
        );
    }
}
