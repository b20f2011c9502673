"""The guided MbICP lesson: steps read from small TOML files, run, and told with their own
numbers."""
