//! Several `gobyd` in one process on the simulator's in-process channel,
//! in virtual time (one [`TokioClock`] under tokio's paused clock), each of
//! which can be killed (its task aborted: nothing of its memory survives,
//! its files stay as written) and started again on the same data
//! directory; every event of every node, in the order seen.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use gobyd::daemon::Daemon;
use gobyd::event::DaemonEvent;
use gobyd::event::TransferEvent;
use gobyd::event::{Control, NetworkRequest};
use modemdriver::sim::medium::Medium;
use modemdriver::sim::SimulatorDriver;
use modemdriver::time::TokioClock;
use protos::goby::apps::protobuf::GobydConfig;
use queue::QueueEvent;
use tokio::sync::{mpsc, oneshot};

/// What a node's clients saw.
#[derive(Debug, Clone)]
pub enum Seen {
    /// A message handed over.
    Delivered {
        node: i32,
        src: i32,
        message: prost_reflect::DynamicMessage,
        route: Option<Vec<i32>>,
    },
    /// An ack of a message this node sent.
    Acked {
        node: i32,
        by: i32,
        message: prost_reflect::DynamicMessage,
        id: Option<u64>,
    },
    /// An expiry of a message this node sent.
    Expired {
        node: i32,
        message: prost_reflect::DynamicMessage,
    },
    /// A transfer's progress.
    Transfer { node: i32, event: TransferEvent },
}

struct Running {
    publisher: mpsc::Sender<gobyd::event::Publish>,
    control: mpsc::Sender<Control>,
    task: tokio::task::JoinHandle<()>,
    stop: Option<oneshot::Sender<()>>,
}

/// The fleet.
pub struct Fleet {
    clock: Arc<TokioClock>,
    medium: Arc<Medium>,
    configs: Vec<GobydConfig>,
    nodes: Vec<Option<Running>>,
    /// Everything seen, in order.
    pub seen: Arc<Mutex<Vec<Seen>>>,
}

impl Fleet {
    /// Starts node `i + 1` from `configs[i]` for each configuration, the
    /// clock reading the system's time now.
    pub async fn start(configs: Vec<GobydConfig>) -> Fleet {
        Fleet::start_with_clock(configs, TokioClock::new()).await
    }

    /// As [`start`](Self::start), the clock reading `now` (microseconds
    /// since the epoch) at the start: the TDMA slots (aligned on the clock)
    /// fall at the same virtual times in every run.
    pub async fn start_at(configs: Vec<GobydConfig>, now: i64) -> Fleet {
        Fleet::start_with_clock(configs, TokioClock::at(now)).await
    }

    async fn start_with_clock(configs: Vec<GobydConfig>, clock: TokioClock) -> Fleet {
        // The daemons' logs, when asked for (e.g. GOBYD_TEST_LOG=info).
        if let Ok(filter) = std::env::var("GOBYD_TEST_LOG") {
            let _ = tracing_subscriber::fmt()
                .with_env_filter(tracing_subscriber::EnvFilter::new(filter))
                .with_test_writer()
                .try_init();
        }
        let mut fleet = Fleet {
            clock: Arc::new(clock),
            medium: Medium::new(),
            nodes: configs.iter().map(|_| None).collect(),
            configs,
            seen: Arc::default(),
        };
        for i in 0..fleet.configs.len() {
            fleet.start_node(i as i32 + 1).await;
        }
        fleet
    }

    /// The water the nodes share (to set a [`Filter`](modemdriver::sim::medium::Filter) on).
    pub fn medium(&self) -> &Arc<Medium> {
        &self.medium
    }

    /// Starts node `id` (again) from its configuration.
    pub async fn start_node(&mut self, id: i32) {
        let config = self.configs[(id - 1) as usize].clone();
        let mut driver_config = config.driver.clone().unwrap();
        driver_config.modem_id = Some(id);
        let driver = SimulatorDriver::start_on_with_clock(
            &driver_config,
            self.medium.clone(),
            self.clock.clone(),
        )
        .unwrap();
        let daemon = Daemon::builder(config)
            .driver(driver)
            .clock(self.clock.clone())
            .start()
            .await
            .expect("gobyd starts");
        let publisher = daemon.publisher();
        let control = daemon.control();
        let mut events = daemon.subscribe();
        let seen = self.seen.clone();
        tokio::spawn(async move {
            while let Ok(e) = events.recv().await {
                let s = match e.as_ref() {
                    DaemonEvent::Received {
                        received,
                        reception,
                    } => Seen::Delivered {
                        node: id,
                        src: received.src,
                        message: received.message.clone(),
                        route: reception.route.as_ref().map(|r| r.to_vec()),
                    },
                    DaemonEvent::Queue {
                        event: QueueEvent::Acked { message, by, .. },
                        entry,
                    } => Seen::Acked {
                        node: id,
                        by: *by,
                        message: message.clone(),
                        id: *entry,
                    },
                    DaemonEvent::Queue {
                        event: QueueEvent::Expired { message, .. },
                        ..
                    } => Seen::Expired {
                        node: id,
                        message: message.clone(),
                    },
                    DaemonEvent::Transfer(event) => Seen::Transfer {
                        node: id,
                        event: event.clone(),
                    },
                    _ => continue,
                };
                seen.lock().unwrap().push(s);
            }
        });
        let (stop, stopped) = oneshot::channel::<()>();
        let task = tokio::spawn(async move {
            daemon
                .run(async move {
                    let _ = stopped.await;
                })
                .await
                .expect("gobyd runs");
        });
        self.nodes[(id - 1) as usize] = Some(Running {
            publisher,
            control,
            task,
            stop: Some(stop),
        });
    }

    /// Kills node `id`: its task is aborted, its memory lost; its files
    /// stay as they were written.
    pub async fn kill(&mut self, id: i32) {
        if let Some(running) = self.nodes[(id - 1) as usize].take() {
            running.task.abort();
            let _ = running.task.await;
        }
    }

    /// Node `id`'s publisher.
    pub fn publisher(&self, id: i32) -> &mpsc::Sender<gobyd::event::Publish> {
        &self.nodes[(id - 1) as usize]
            .as_ref()
            .expect("the node runs")
            .publisher
    }

    /// Asks node `id`'s network layer `request`.
    pub async fn network(
        &self,
        id: i32,
        request: NetworkRequest,
    ) -> Result<serde_json::Value, String> {
        let (reply, answer) = oneshot::channel();
        self.nodes[(id - 1) as usize]
            .as_ref()
            .expect("the node runs")
            .control
            .send(Control::Network { request, reply })
            .await
            .expect("the daemon takes requests");
        answer
            .await
            .expect("the daemon answers")
            .map(|reply| serde_json::to_value(gobyd::json::network_reply(&reply)).unwrap())
    }

    /// Stops every node.
    pub async fn stop(mut self) {
        for running in self.nodes.iter_mut().filter_map(Option::take) {
            if let Some(stop) = running.stop {
                let _ = stop.send(());
            }
            let _ = running.task.await;
        }
    }

    /// How many things seen `f` picks.
    pub fn count(&self, f: impl Fn(&Seen) -> bool) -> usize {
        self.seen.lock().unwrap().iter().filter(|s| f(s)).count()
    }

    /// What was seen, so far.
    pub fn seen(&self) -> Vec<Seen> {
        self.seen.lock().unwrap().clone()
    }
}

/// The data directory of node `id` under `dir`.
pub fn data_dir(dir: &Path, id: i32) -> PathBuf {
    dir.join(format!("data{id}"))
}
