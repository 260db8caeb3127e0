//! Label tables and confidence-based 2D label consensus (METHOD.md §5).
