"""The harness the language-side benchmarks share: sandboxed sessions, the oracle endpoint, runs and reports."""
