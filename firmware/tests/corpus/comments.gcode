G1 (unterminated X1
;only comment
(only)
