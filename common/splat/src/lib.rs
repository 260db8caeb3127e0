//! 3D Gaussian map and the GS Voting rasterizer (METHOD.md §1–3).
