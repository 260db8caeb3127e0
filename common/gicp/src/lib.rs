//! Generalized-ICP registration (METHOD.md §7).
