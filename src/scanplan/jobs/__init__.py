"""One module per user job; each composes the stages below it. The CLI parses and prints."""
