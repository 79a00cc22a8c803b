"""STAND-IN package until issue 3 lands plls_bench/repr; replaced by issue 3's at that merge."""
