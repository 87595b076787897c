"""The reference path library, installed as package data (see README.md here)."""
