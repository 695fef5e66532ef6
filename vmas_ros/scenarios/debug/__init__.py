"""VMAS's debug scenarios: small worlds that exercise one engine feature each."""
