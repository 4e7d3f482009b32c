use std::fmt;

/// Errors the core reports instead of panicking; the bindings turn them into Python exceptions.
#[derive(Debug, Clone, PartialEq)]
pub enum CoreError {
    /// A point has a NaN or infinite coordinate.
    NonFinite { row: usize },
    /// No points were given where at least one is needed.
    Empty,
    /// An argument is out of its valid range.
    InvalidArgument(String),
    /// A covariance is not symmetric positive-definite.
    NotPositiveDefinite { component: usize },
}

impl fmt::Display for CoreError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            CoreError::NonFinite { row } => {
                write!(
                    f,
                    "points contain NaN or infinite values (first at row {row})"
                )
            }
            CoreError::Empty => write!(f, "no points given"),
            CoreError::InvalidArgument(msg) => write!(f, "{msg}"),
            CoreError::NotPositiveDefinite { component } => {
                write!(
                    f,
                    "covariance of component {component} is not positive-definite"
                )
            }
        }
    }
}

impl std::error::Error for CoreError {}
