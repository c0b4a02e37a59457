"""Analysis of the controller: frequency responses of its linearisations."""
