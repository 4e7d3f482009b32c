//! `gmmap-ros2dds-bridge CONFIG.json5`: zenoh-plugin-ros2dds in a Zenoh runtime, as
//! zenoh-bridge-ros2dds runs it, for gmmap's tests against real DDS traffic.
//!
//! The configuration is Zenoh's own file format; the plugin's settings live under
//! `plugins.ros2dds` (domain, namespace, ros_localhost_only, ...). The host turns on what the
//! plugin needs whatever the file says: timestamps (its cache of TRANSIENT_LOCAL publications
//! needs them), the admin space and plugin loading. It runs until SIGINT or SIGTERM.

use std::process::ExitCode;

use zenoh::config::Config;
use zenoh::internal::plugins::PluginsManager;
use zenoh::internal::runtime::RuntimeBuilder;
use zenoh_plugin_trait::Plugin;

fn load(path: &str) -> Result<Config, String> {
    let mut config = Config::from_file(path).map_err(|e| format!("{path}: {e}"))?;
    config
        .insert_json5("timestamping/enabled", "true")
        .and_then(|_| config.insert_json5("adminspace/enabled", "true"))
        .and_then(|_| config.insert_json5("plugins_loading/enabled", "true"))
        .map_err(|e| format!("{path}: {e}"))?;
    if config.plugin("ros2dds").is_none() {
        return Err(format!("{path}: no plugins.ros2dds section"));
    }
    Ok(config)
}

#[tokio::main]
async fn main() -> ExitCode {
    zenoh::init_log_from_env_or("warn");
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 2 || args[1] == "--help" || args[1] == "-h" {
        eprintln!("usage: {} CONFIG.json5", args[0]);
        eprintln!(
            "zenoh-plugin-ros2dds {}",
            zenoh_plugin_ros2dds::ROS2Plugin::PLUGIN_VERSION
        );
        return ExitCode::from(2);
    }
    let config = match load(&args[1]) {
        Ok(config) => config,
        Err(e) => {
            eprintln!("gmmap-ros2dds-bridge: {e}");
            return ExitCode::from(2);
        }
    };
    let mut plugins = PluginsManager::static_plugins_only();
    plugins.declare_static_plugin::<zenoh_plugin_ros2dds::ROS2Plugin, &str>("ros2dds", true);
    let mut runtime = match RuntimeBuilder::new(config)
        .plugins_manager(plugins)
        .build()
        .await
    {
        Ok(runtime) => runtime,
        Err(e) => {
            eprintln!("gmmap-ros2dds-bridge: cannot build the Zenoh runtime: {e}");
            return ExitCode::FAILURE;
        }
    };
    if let Err(e) = runtime.start().await {
        eprintln!("gmmap-ros2dds-bridge: cannot start the Zenoh runtime: {e}");
        return ExitCode::FAILURE;
    }
    // Tests read this line to know the bridge is up.
    println!("ready");
    let mut term = tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
        .expect("a SIGTERM handler");
    tokio::select! {
        _ = tokio::signal::ctrl_c() => {},
        _ = term.recv() => {},
    }
    ExitCode::SUCCESS
}
