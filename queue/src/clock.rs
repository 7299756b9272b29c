//! Time source of the queues: the workspace's one clock (`goby-time`),
//! injectable so that tests and simulations run exactly and instantly.

pub use goby_time::{
    seconds_to_micros, Clock, ManualClock, Micros, SystemClock, MICROS_PER_SECOND,
};
