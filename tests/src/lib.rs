//! End-to-end tests that launch the real processes live in tests/tests/.
