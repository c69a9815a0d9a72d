"""Figure helpers of the book chapters: the computations behind a chapter's drawings, kept in the
package so that the chapters import them (the book never re-implements package code)."""
