//! iceoryx2 helpers: run-namespaced nodes, zero-copy publish, WaitSet subscribe, shutdown.
