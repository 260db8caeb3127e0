//! The 16×16 tile grid over the image.

/// Tile edge in pixels (3DGS BLOCK_X / BLOCK_Y).
pub const TILE_SIZE: u32 = 16;
/// Pixels per tile.
pub const TILE_PIXELS: usize = (TILE_SIZE * TILE_SIZE) as usize;

/// Image size and its tile grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TileGrid {
    pub width: u32,
    pub height: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
}

impl TileGrid {
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            tiles_x: width.div_ceil(TILE_SIZE),
            tiles_y: height.div_ceil(TILE_SIZE),
        }
    }

    pub fn tile_count(&self) -> usize {
        self.tiles_x as usize * self.tiles_y as usize
    }

    /// Tiles holding any pixel of [cx − hw, cx + hw] × [cy − hh, cy + hh] (exclusive upper bounds).
    pub fn tiles_of_box(&self, center: [f32; 2], half_w: f32, half_h: f32) -> TileRect {
        let t = TILE_SIZE as f32;
        let lo = |v: f32, n: u32| ((v.ceil() / t).floor().max(0.0) as u32).min(n);
        let hi = |v: f32, n: u32| (((v.floor() / t).floor() + 1.0).max(0.0) as u32).min(n);
        TileRect {
            x0: lo(center[0] - half_w, self.tiles_x),
            y0: lo(center[1] - half_h, self.tiles_y),
            x1: hi(center[0] + half_w, self.tiles_x),
            y1: hi(center[1] + half_h, self.tiles_y),
        }
    }
}

/// A rectangle of tiles, upper bounds exclusive.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct TileRect {
    pub x0: u32,
    pub y0: u32,
    pub x1: u32,
    pub y1: u32,
}

impl TileRect {
    pub const EMPTY: TileRect = TileRect {
        x0: 0,
        y0: 0,
        x1: 0,
        y1: 0,
    };

    pub fn is_empty(&self) -> bool {
        self.x1 <= self.x0 || self.y1 <= self.y0
    }

    pub fn area(&self) -> usize {
        if self.is_empty() {
            0
        } else {
            (self.x1 - self.x0) as usize * (self.y1 - self.y0) as usize
        }
    }

    pub fn contains(&self, tx: u32, ty: u32) -> bool {
        tx >= self.x0 && tx < self.x1 && ty >= self.y0 && ty < self.y1
    }

    pub fn intersect(&self, o: &TileRect) -> TileRect {
        let r = TileRect {
            x0: self.x0.max(o.x0),
            y0: self.y0.max(o.y0),
            x1: self.x1.min(o.x1),
            y1: self.y1.min(o.y1),
        };
        if r.is_empty() {
            TileRect::EMPTY
        } else {
            r
        }
    }
}
