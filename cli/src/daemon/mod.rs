//! `gobyd`, the daemon between a modem and an autonomy process: it composes
//! DCCL, the queue, medium access and a modem driver from one configuration
//! and connects them to the vehicle's autonomy software.

pub mod config;
pub mod json_protocol;
pub mod json_server;
pub mod moos_bridge;
pub mod outbox;
pub mod raw_log;
pub mod runtime;

use std::io::{IsTerminal, Write};

use protos::goby::apps::protobuf::{gobyd_config::JsonInterface, GobydConfig};

use crate::{GobydCli, EXIT_OK, EXIT_SETUP};

/// The configuration named by the command line, with its overrides applied.
fn configuration(cli: &GobydCli) -> Result<GobydConfig, config::ConfigError> {
    let mut config = match &cli.config {
        Some(path) => config::load(path)?,
        None => GobydConfig::default(),
    };
    if let Some(id) = cli.modem_id {
        config.modem_id = Some(id);
        for id_field in [
            config.driver.as_mut().map(|d| &mut d.modem_id),
            config.mac.as_mut().map(|m| &mut m.modem_id),
            config.queue.as_mut().map(|q| &mut q.modem_id),
        ]
        .into_iter()
        .flatten()
        {
            *id_field = Some(id);
        }
    }
    if let Some(dir) = &cli.data_dir {
        config.data_dir = Some(dir.display().to_string());
    }
    if let Some(addr) = &cli.json_tcp {
        config
            .json
            .get_or_insert_with(JsonInterface::default)
            .tcp_bind = Some(addr.clone());
    }
    if cli.log_json {
        config.log.get_or_insert_with(Default::default).json = Some(true);
    }
    Ok(config)
}

/// Sets up logging to standard error: human-readable, or JSON objects.
fn init_logging(config: &GobydConfig) {
    let log = config.log.clone().unwrap_or_default();
    let filter = tracing_subscriber::EnvFilter::try_new(log.level())
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info"));
    let builder = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal());
    let _ = if log.json() {
        builder.json().try_init()
    } else {
        builder.try_init()
    };
}

/// Completes on SIGINT or SIGTERM.
async fn shutdown_signal() {
    let interrupt = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        use tokio::signal::unix::{signal, SignalKind};
        match signal(SignalKind::terminate()) {
            Ok(mut terminate) => {
                tokio::select! {
                    _ = interrupt => {}
                    _ = terminate.recv() => {}
                }
            }
            Err(_) => {
                let _ = interrupt.await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = interrupt.await;
    }
    tracing::info!("signal received: shutting down");
}

/// Runs `gobyd` with a parsed command line; returns the exit status.
pub fn run_cli(cli: GobydCli) -> u8 {
    if cli.example_config {
        let mut out = std::io::stdout().lock();
        return match out.write_all(config::EXAMPLE_CONFIG.as_bytes()) {
            Ok(()) => EXIT_OK,
            Err(_) => EXIT_SETUP,
        };
    }
    let config = match configuration(&cli) {
        Ok(config) => config,
        Err(e) => {
            eprintln!("gobyd: error: {e}");
            return EXIT_SETUP;
        }
    };
    if cli.check {
        return match runtime::check(config) {
            Ok(types) => {
                println!("configuration is valid; DCCL types: {}", types.join(", "));
                EXIT_OK
            }
            Err(e) => {
                eprintln!("gobyd: error: {e}");
                EXIT_SETUP
            }
        };
    }
    init_logging(&config);
    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("gobyd: error: cannot start the runtime: {e}");
            return EXIT_SETUP;
        }
    };
    runtime.block_on(async {
        let daemon = match runtime::Daemon::start(config).await {
            Ok(d) => d,
            Err(e) => {
                eprintln!("gobyd: error: {e}");
                return EXIT_SETUP;
            }
        };
        if let Some(addr) = daemon.json_tcp_addr() {
            tracing::info!("JSON interface on tcp://{addr}");
        }
        match daemon.run(shutdown_signal()).await {
            Ok(()) => EXIT_OK,
            Err(e) => {
                eprintln!("gobyd: error: {e}");
                EXIT_SETUP
            }
        }
    })
}
