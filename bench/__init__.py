"""flowtact's benchmark suites (installed as flowtact.bench; run them with `flowtact bench`, see bench/README.md)."""
