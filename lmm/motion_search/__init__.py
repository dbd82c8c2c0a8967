"""Motion search by example: pose windows of any skeleton, embeddings, a cached index and DTW re-ranking."""
