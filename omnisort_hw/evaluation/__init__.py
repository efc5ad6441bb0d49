"""Experiments on simulated data with ground truth: the paper's Table 3 comparison
(`table3`), the random-scene sorting experiment (`sorting`) and every method on the authors'
own renders against their published settings (`reference_accuracy`)."""
