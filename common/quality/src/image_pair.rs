//! Shared size check of a (render, target, mask) triple.

/// Asserts one render pixel, three target bytes and one mask entry per pixel.
pub(crate) fn check_sizes(rendered: &[[f32; 3]], target_rgb8: &[u8], valid: &[bool]) {
    assert_eq!(
        rendered.len() * 3,
        target_rgb8.len(),
        "render and RGB8 target sizes differ"
    );
    assert_eq!(rendered.len(), valid.len(), "render and mask sizes differ");
}
