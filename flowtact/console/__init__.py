"""What every command shares on the terminal: one error path, `--debug` tracebacks, the progress bar."""
