"""What others give flowtact, read within documented bounds and shown as data: the limits every value and flag is checked against, files read within bounds, untrusted text made safe to print."""
