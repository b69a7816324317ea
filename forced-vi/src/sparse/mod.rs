//! Large models: sparse node kernels and the sparse step (DESIGN §9).

mod node;

pub use node::{Block, NodeBlocks, NodePattern, NodeSink, SparseNode};
