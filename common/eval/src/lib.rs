//! Evaluation metrics (METHOD.md §9).
