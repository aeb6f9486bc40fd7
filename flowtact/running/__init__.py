"""From a loaded graph to a finished run, above the runtime: compiling a graph, launching it, when played-back runs end, the command line of Python children."""
