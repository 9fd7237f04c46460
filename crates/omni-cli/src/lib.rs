//! The small CLI layer every omniscan binary shares: errors, exit codes, stdin/stdout, progress.
