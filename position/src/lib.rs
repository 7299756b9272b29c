//! # Position telemetry over slow links
//!
//! Sends a vehicle's position history at a fixed sample period τ for a few
//! bits per sample (T. Schneider's 2013 thesis, chapter 3): sender and
//! receiver run the same state observer on the positions already
//! transmitted, and only the difference between the measured position and
//! the observer's prediction, `dy[n] = y[n] − H·x̂_prior[n]`, is sent,
//! arithmetic coded with a probability model both ends share.
//!
//! - [`config`]: the parameters both ends agree on (observer, model, τ, ...).
//! - [`fixed_speed`], [`kalman`], [`observer`]: the two state observers.
//! - [`model`]: uniform, Gaussian and adaptive models of the deltas.
//! - [`sample_coder`]: one sample as a full or delta transmission.
//! - [`frame`]: DCCL frames (`goby.position.protobuf.PositionFrame`, user
//!   codec `goby.position`), [`PositionSender`] and [`PositionReceiver`].
//! - [`trajectory`], [`synth`], [`eval`]: trajectory files, synthetic AUV
//!   trajectories and the evaluation of thesis Table 3.2 and Fig. 3.10a.
//!
//! ```
//! use position::{PositionConfig, PositionReceiver, PositionSender, Sample};
//!
//! let config = PositionConfig::default();
//! let mut tx = PositionSender::new(config.clone())?;
//! let mut rx = PositionReceiver::new(config)?;
//! for n in 0..20 {
//!     let t = 1000.0 + 10.0 * n as f64;
//!     tx.push(Sample { t, position: [15.0 * n as f64, 3.2, -20.0] })?;
//! }
//! let frame = tx.next_frame(32)?.expect("samples queued");
//! let received = rx.receive(&frame)?;
//! assert_eq!(received[0].position, [0.0, 3.0, -20.0]); // 1 m resolution
//! assert_eq!(received[5].t, 1050.0);
//! # Ok::<(), position::PositionError>(())
//! ```

#![warn(missing_docs)]

pub mod config;
mod error;
pub mod eval;
pub mod fixed_speed;
pub mod frame;
pub mod kalman;
pub mod model;
pub mod observer;
pub mod sample_coder;
pub mod synth;
pub mod trajectory;

pub use config::{ModelKind, ObserverKind, PositionConfig};
pub use error::PositionError;
pub use frame::{PositionReceiver, PositionSender};
pub use sample_coder::{Sample, SampleCoder, Transmission};

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;
