"""Graph files shipped with flowtact (found by name: `flowtact run touch`)."""
