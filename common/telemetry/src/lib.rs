//! Per-stage latency records, histograms and Chrome traces.
