"""Conspicuity trials with people: the study file, the web app participants use, their responses."""
