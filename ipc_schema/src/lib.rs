//! Message contract between pipeline processes.
