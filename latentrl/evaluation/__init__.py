"""Policy and motion evaluation: pure metrics, path suites, runner and reports."""
