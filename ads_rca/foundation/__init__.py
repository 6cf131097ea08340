"""What every layer stands on and no domain owns: errors in words, strict JSON out, safe file
reads, geometry, progress, forked workers and a quick exit."""
