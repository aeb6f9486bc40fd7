"""The graph file and its checks: YAML read with locations and under limits, validated into a Graph (nodes, edges, deployment, replays, file paths, extras)."""
