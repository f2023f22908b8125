//! The error of the benchmark commands' bodies ([`RunError`]) and the anyhow-like helpers they
//! use to say what failed: [`Context`] on results and options, [`bail!`] and [`ensure!`].
//!
//! Contract: an error's text and its causes are exactly those the command line printed when
//! these bodies lived in the binary with `anyhow`: a context is its own line of the chain, the
//! error it wraps the next (its [`std::error::Error::source`]); a wrapped error without context
//! is transparent (its own text and causes, as `?` into `anyhow` gave).

use std::error::Error as StdError;
use std::fmt::Display;

/// Why a benchmark command failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
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
        source: Box<dyn StdError + Send + Sync + 'static>,
    },
    /// Another error, passed on as it is.
    #[error(transparent)]
    Other(Box<dyn StdError + Send + Sync + 'static>),
}

impl RunError {
    /// Any error, passed on as it is.
    pub fn other(e: impl StdError + Send + Sync + 'static) -> Self {
        Self::Other(Box::new(e))
    }
}

/// The errors a `?` passes on as they are.
macro_rules! passed_on {
    ($($t:ty),* $(,)?) => {
        $(impl From<$t> for RunError {
            fn from(e: $t) -> Self {
                Self::Other(Box::new(e))
            }
        })*
    };
}
passed_on!(
    std::io::Error,
    serde_json::Error,
    crate::BenchError,
    ellipso_report::ReportError,
    ellipso_report::output::OutputError,
    ellipso_sim::scene::error::SceneError,
    ellipso_sim::render::RenderError,
    ellipso_polar::frame::FrameError,
    ellipso_vision::pose::DetectError,
    ellipso_vision::track::TrackRejection,
    ellipso_vision::calibrate::CalibError,
);

/// `anyhow::Context` for the bench bodies: the context becomes the error's text, the error its
/// cause; a `None` becomes the context alone.
pub trait Context<T> {
    /// Wraps the error in `context`.
    fn context<C: Display>(self, context: C) -> Result<T, RunError>;
    /// Wraps the error in the context `f` makes (only on failure).
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T, RunError>;
}

impl<T, E: StdError + Send + Sync + 'static> Context<T> for Result<T, E> {
    fn context<C: Display>(self, context: C) -> Result<T, RunError> {
        self.map_err(|e| RunError::Context {
            context: context.to_string(),
            source: Box::new(e),
        })
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T, RunError> {
        self.map_err(|e| RunError::Context {
            context: f().to_string(),
            source: Box::new(e),
        })
    }
}

impl<T> Context<T> for Option<T> {
    fn context<C: Display>(self, context: C) -> Result<T, RunError> {
        self.ok_or_else(|| RunError::Msg(context.to_string()))
    }
    fn with_context<C: Display, F: FnOnce() -> C>(self, f: F) -> Result<T, RunError> {
        self.ok_or_else(|| RunError::Msg(f().to_string()))
    }
}

/// Returns a [`RunError::Msg`] made like `format!`.
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::error::RunError::Msg(format!($($arg)*)))
    };
}

/// [`bail!`] unless the condition holds.
macro_rules! ensure {
    ($cond:expr, $($arg:tt)*) => {
        if !$cond {
            $crate::error::bail!($($arg)*);
        }
    };
}

pub(crate) use {bail, ensure};

/// Where a benchmark command's lines go: the binary prints them (stdout, stderr); the library
/// never prints itself.
pub trait Say {
    /// One line of the command's output (stdout), without its newline.
    fn out(&self, line: std::fmt::Arguments<'_>);
    /// One line of progress or warning (stderr), without its newline.
    fn err(&self, line: std::fmt::Arguments<'_>);
}

/// `println!` into a [`Say`].
macro_rules! say {
    ($say:expr) => {
        $say.out(format_args!(""))
    };
    ($say:expr, $($arg:tt)*) => {
        $say.out(format_args!($($arg)*))
    };
}

pub(crate) use say;
