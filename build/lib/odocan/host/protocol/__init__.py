"""The bus protocol on the host side: DBC decoding, E2E checks, the command encoder."""
