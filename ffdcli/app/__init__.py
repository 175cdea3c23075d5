"""One workflow per command, from files in to a report value out (the CLI and the API call these)."""
