"""Language side: maneuvers, baseline instructions, intent classifier, counterfactual families."""
