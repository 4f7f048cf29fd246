//! Size limits shared by the readers, the generator and the store. Each bounds what one file, flag or option can
//! make the program allocate or compute, and says why its value is safe for real data.

/// Most frames in one clip (a baked glTF animation, a procedural clip, a store window): 5.5 minutes at 30 fps,
/// far beyond the 16–31-frame windows of the method, while one bogus key time or flag cannot ask for millions.
pub const MAX_FRAMES: usize = 10_000;
/// Most vertex rows (frames × vertices) of one clip: 2^26 rows are 768 MiB of f32 coordinates.
pub const MAX_CLIP_VERTICES: usize = 1 << 26;
/// Most vertices of a procedural clip: the shapes are made for 512–4096 vertices; 2^16 leaves room and keeps one
/// clip's geometry work small.
pub const MAX_SYNTH_VERTICES: usize = 1 << 16;
/// Most procedural clips one synth run writes: 2^24 index rows and jobs stay within a few GiB of memory.
pub const MAX_SYNTH_CLIPS: usize = 1 << 24;
/// Most FPS tokens P per clip: the method uses 512; 2^16 bounds the index arrays and the O(P · N) sampling.
pub const MAX_P: usize = 1 << 16;
