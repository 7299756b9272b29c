//! Time source of the medium access control: the workspace's one clock
//! (`goby-time`), injectable so that tests and simulations run exactly and
//! instantly.

pub use goby_time::{
    micros_to_seconds, seconds_to_micros, Clock, ManualClock, Micros, SystemClock, MICROS_PER_DAY,
    MICROS_PER_SECOND,
};
