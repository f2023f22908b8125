//! `ellipso-run-error`: the error of the library functions the `ellipso` subcommands call
//! ([`RunError`]), and the anyhow-like helpers their bodies use to say what failed: [`Context`]
//! on results and options, [`bail!`](crate::bail) and [`ensure!`](crate::ensure); and [`Say`],
//! where their lines go.
//!
//! A crate of its own, not part of the numeric core (`ellipso-model`): it is the command line's
//! error machinery, which the optics, the camera model and the geometry never need; every crate
//! with a subcommand's body depends on it, and it depends on none of ours.
//!
//! Contract: an error's text and its causes are exactly those the command line printed when
//! these bodies lived in the binary with `anyhow`: a context is its own link of the chain, the
//! error it wraps the next ([`std::error::Error::source`]); an error passed on by `?` without
//! context is transparent (its own text and causes). Any error converts with `?`, so
//! [`RunError`] itself is not a [`std::error::Error`]: the binary turns it into one with
//! [`RunError::into_boxed`] (its chain unchanged). Libraries never print: they hand each line
//! to a [`Say`].

use std::error::Error as StdError;
use std::fmt::{self, Display};

/// A boxed error that crosses threads.
pub type BoxedError = Box<dyn StdError + Send + Sync + 'static>;

/// What [`RunError`] holds.
#[derive(Debug, thiserror::Error)]
pub enum RunErrorKind {
    /// A message of its own (no cause).
    #[error("{0}")]
    Msg(String),
    /// What was being done, and the error that stopped it.
    #[error("{context}")]
    Context {
        /// What was being done.
        context: String,
        /// The cause.
        #[source]
        source: BoxedError,
    },
    /// Another error, passed on as it is.
    #[error(transparent)]
    Other(BoxedError),
}

/// Why a subcommand's library function failed (module doc).
pub struct RunError(Box<RunErrorKind>);

impl RunError {
    /// A message of its own.
    pub fn msg(text: impl Display) -> Self {
        Self(Box::new(RunErrorKind::Msg(text.to_string())))
    }
    /// Another error, already boxed (an `anyhow::Error` turns into one), passed on as it is.
    pub fn from_boxed(e: BoxedError) -> Self {
        Self(Box::new(RunErrorKind::Other(e)))
    }
    /// What it holds.
    pub fn kind(&self) -> &RunErrorKind {
        &self.0
    }
    /// As a standard error, its text and causes unchanged (for `anyhow` in the binary).
    pub fn into_boxed(self) -> BoxedError {
        self.0
    }
    fn with(context: impl Display, source: BoxedError) -> Self {
        Self(Box::new(RunErrorKind::Context {
            context: context.to_string(),
            source,
        }))
    }
}

impl fmt::Debug for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&self.0, f)
    }
}

impl Display for RunError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        Display::fmt(&self.0, f)
    }
}

impl<E: StdError + Send + Sync + 'static> From<E> for RunError {
    fn from(e: E) -> Self {
        Self(Box::new(RunErrorKind::Other(Box::new(e))))
    }
}

/// `anyhow::Context` for the subcommands' bodies: the context becomes the error's text, the
/// error its cause; a `None` becomes the context alone.
pub trait Context<T> {
    /// Wraps the error in `context`.
    fn context<C: Display>(self, context: C) -> Result<T, RunError>;
    /// Wraps the error in the context `f` makes (only on failure).
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T, RunError>;
}

impl<T, E: StdError + Send + Sync + 'static> Context<T> for Result<T, E> {
    fn context<C: Display>(self, context: C) -> Result<T, RunError> {
        self.map_err(|e| RunError::with(context, Box::new(e)))
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T, RunError> {
        self.map_err(|e| RunError::with(f(), Box::new(e)))
    }
}

impl<T> Context<T> for Result<T, RunError> {
    fn context<C: Display>(self, context: C) -> Result<T, RunError> {
        self.map_err(|e| RunError::with(context, e.into_boxed()))
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T, RunError> {
        self.map_err(|e| RunError::with(f(), e.into_boxed()))
    }
}

impl<T> Context<T> for Option<T> {
    fn context<C: Display>(self, context: C) -> Result<T, RunError> {
        self.ok_or_else(|| RunError::msg(context))
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T, RunError> {
        self.ok_or_else(|| RunError::msg(f()))
    }
}

/// Returns a [`RunError`] message made like `format!`.
#[macro_export]
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::RunError::msg(format!($($arg)*)))
    };
}

/// [`bail!`] unless the condition holds.
#[macro_export]
macro_rules! ensure {
    ($cond:expr, $($arg:tt)*) => {
        if !$cond {
            $crate::bail!($($arg)*);
        }
    };
}

/// Where a subcommand's lines go: the binary prints them (stdout, stderr); the libraries never
/// print themselves. `Sync`: parallel stages say lines too.
pub trait Say: Sync {
    /// One line of the command's output (stdout), without its newline.
    fn out(&self, line: fmt::Arguments<'_>);
    /// One line of progress or warning (stderr), without its newline.
    fn err(&self, line: fmt::Arguments<'_>);
}

/// A [`Say`] that drops every line: for callers that run a command's body for its result
/// alone (a bench's own copy of a stage, a test that looks at the files).
pub struct Silent;

impl Say for Silent {
    fn out(&self, _: fmt::Arguments<'_>) {}
    fn err(&self, _: fmt::Arguments<'_>) {}
}

/// `println!` into a [`Say`].
#[macro_export]
macro_rules! say {
    ($say:expr) => {
        $say.out(format_args!(""))
    };
    ($say:expr, $($arg:tt)*) => {
        $say.out(format_args!($($arg)*))
    };
}

#[cfg(test)]
mod tests {
    use super::*;

    fn chain(e: &(dyn StdError + 'static)) -> Vec<String> {
        let mut out = vec![e.to_string()];
        let mut cause = e.source();
        while let Some(c) = cause {
            out.push(c.to_string());
            cause = c.source();
        }
        out
    }

    #[test]
    fn contexts_and_passed_on_errors_keep_anyhows_chain() {
        let io = || std::io::Error::other("disk full");
        let passed = RunError::from(io());
        let boxed = passed.into_boxed();
        assert_eq!(chain(boxed.as_ref()), ["disk full"]);
        let inner: Result<(), _> = Err(io());
        let outer = inner.context("writing a").context("saving b");
        let boxed = outer.unwrap_err().into_boxed();
        assert_eq!(
            chain(boxed.as_ref()),
            ["saving b", "writing a", "disk full"]
        );
        let none: Option<u8> = None;
        assert_eq!(
            none.context("no value").unwrap_err().to_string(),
            "no value"
        );
    }
}
