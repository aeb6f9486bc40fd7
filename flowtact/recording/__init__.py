"""HDF5 recordings: the crash-safe writer and reader, their checksums and bounded reads, and what `flowtact info` shows."""
