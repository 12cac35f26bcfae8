//! The CLIP tokenizer of Stable Diffusion's text encoder (#45): lower-cased, byte-level BPE,
//! 77 tokens with `<|startoftext|>` (49406) first and `<|endoftext|>` (49407) after the text,
//! padded with `<|endoftext|>` (SD 1.x) or id 0 (SD 2).
//!
//! Built on the `tokenizers` crate (its BPE model, normalisers and pre-tokenisers, without the
//! C-built Oniguruma: `fancy-regex`), configured as Hugging Face's `CLIPTokenizerFast` is: NFC,
//! runs of whitespace to one space, lower case; split on CLIP's pattern; byte-level; BPE with
//! the `</w>` end-of-word suffix. The vocabulary comes either from a model folder's
//! `vocab.json` + `merges.txt` (diffusers' and optimum's exports) or from OpenAI's merges list
//! (`bpe_simple_vocab_16e6.txt.gz`, as `open_clip` ships it), from which the vocabulary is
//! built as CLIP builds it: the 256 byte symbols, the same with `</w>`, the first 48 894 merges,
//! the two special tokens — 49 408 entries.
//!
//! Not done: CLIP's `ftfy` text repair and HTML unescaping (Python-only libraries); prompts are
//! taken as typed.

use crate::error::{Error, Result};
use std::path::Path;
use tokenizers::models::bpe::{BPE, Vocab};
use tokenizers::normalizers::{Lowercase, NFC, Replace, Sequence as NormalizerSequence};
use tokenizers::pre_tokenizers::byte_level::ByteLevel;
use tokenizers::pre_tokenizers::sequence::Sequence as PreTokenizerSequence;
use tokenizers::pre_tokenizers::split::{Split, SplitPattern};
use tokenizers::{SplitDelimiterBehavior, Tokenizer};

/// Tokens the text encoder takes.
pub const CONTEXT_LENGTH: usize = 77;
/// `<|startoftext|>`.
pub const BOS: u32 = 49406;
/// `<|endoftext|>`.
pub const EOS: u32 = 49407;
/// Merges CLIP uses from the merges list (49 152 − 256 − 2).
const CLIP_MERGES: usize = 48_894;
/// CLIP's split pattern (HF `CLIPTokenizerFast`).
const PATTERN: &str =
    r"<\|startoftext\|>|<\|endoftext\|>|'s|'t|'re|'ve|'m|'ll|'d|[\p{L}]+|[\p{N}]|[^\s\p{L}\p{N}]+";

/// What fills the sequence after `<|endoftext|>`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ClipPadding {
    /// `<|endoftext|>` again (SD 1.x's tokenizer).
    EndOfText,
    /// Id 0 (SD 2's).
    Zero,
}

/// A prompt as the text encoder takes it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ClipTokens {
    /// [`CONTEXT_LENGTH`] ids.
    pub ids: Vec<u32>,
    /// The prompt's tokens before truncation (without the two special ones).
    pub prompt_tokens: usize,
    /// Whether the prompt was cut to fit (75 tokens of text at most).
    pub truncated: bool,
}

/// GPT-2's byte-to-symbol table (printable Latin-1 bytes stand for themselves, the others for
/// U+0100…), in CLIP's vocabulary order.
fn byte_symbols() -> Vec<char> {
    let mut bytes: Vec<u32> = (b'!' as u32..=b'~' as u32)
        .chain(0xA1..=0xAC)
        .chain(0xAE..=0xFF)
        .collect();
    let mut chars: Vec<u32> = bytes.clone();
    let mut n = 0;
    for b in 0..256u32 {
        if !bytes.contains(&b) {
            bytes.push(b);
            chars.push(256 + n);
            n += 1;
        }
    }
    chars.into_iter().filter_map(char::from_u32).collect()
}

/// The CLIP tokenizer.
pub struct ClipTokenizer {
    inner: Tokenizer,
    padding: ClipPadding,
}

impl std::fmt::Debug for ClipTokenizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ClipTokenizer")
            .field("padding", &self.padding)
            .finish()
    }
}

impl ClipTokenizer {
    /// From OpenAI's merges list (the text of `bpe_simple_vocab_16e6.txt`: a version line,
    /// then one merge per line).
    pub fn from_clip_merges(text: &str, padding: ClipPadding) -> Result<Self> {
        let merges: Vec<(String, String)> = text
            .lines()
            .skip(1)
            .take(CLIP_MERGES)
            .map(|l| {
                let mut parts = l.split(' ');
                match (parts.next(), parts.next(), parts.next()) {
                    (Some(a), Some(b), None) => Ok((a.to_string(), b.to_string())),
                    _ => Err(Error::invalid(format!(
                        "CLIP merges: a line is not a pair: {l:?}"
                    ))),
                }
            })
            .collect::<Result<_>>()?;
        if merges.len() != CLIP_MERGES {
            return Err(Error::invalid(format!(
                "CLIP merges: {} merges, not {CLIP_MERGES}",
                merges.len()
            )));
        }
        let symbols = byte_symbols();
        let mut words: Vec<String> = symbols.iter().map(|c| c.to_string()).collect();
        words.extend(symbols.iter().map(|c| format!("{c}</w>")));
        words.extend(merges.iter().map(|(a, b)| format!("{a}{b}")));
        words.push("<|startoftext|>".into());
        words.push("<|endoftext|>".into());
        let vocab: Vocab = words
            .into_iter()
            .enumerate()
            .map(|(i, w)| (w, i as u32))
            .collect();
        Self::build(vocab, merges, padding)
    }

    /// From a gzip-compressed merges list (`bpe_simple_vocab_16e6.txt.gz`).
    pub fn from_clip_merges_gz(path: &Path, padding: ClipPadding) -> Result<Self> {
        use std::io::Read;
        let file = std::fs::File::open(path).map_err(|e| Error::file(path, e))?;
        let mut text = String::new();
        flate2::read::GzDecoder::new(file)
            .read_to_string(&mut text)
            .map_err(|e| Error::file(path, format!("not a gzip-compressed merges list ({e})")))?;
        Self::from_clip_merges(&text, padding).map_err(|e| Error::file(path, e.to_string()))
    }

    /// From Hugging Face's `vocab.json` and `merges.txt` (a model folder's `tokenizer/`).
    pub fn from_vocab_and_merges(
        vocab: &Path,
        merges: &Path,
        padding: ClipPadding,
    ) -> Result<Self> {
        let text = std::fs::read_to_string(vocab).map_err(|e| Error::file(vocab, e))?;
        let map: std::collections::HashMap<String, u32> = serde_json::from_str(&text)
            .map_err(|e| Error::file(vocab, format!("not a vocabulary ({e})")))?;
        let merges_text = std::fs::read_to_string(merges).map_err(|e| Error::file(merges, e))?;
        let pairs: Vec<(String, String)> = merges_text
            .lines()
            .filter(|l| !l.starts_with("#version") && !l.trim().is_empty())
            .map(|l| {
                l.split_once(' ')
                    .map(|(a, b)| (a.to_string(), b.to_string()))
                    .ok_or_else(|| Error::file(merges, format!("a line is not a pair: {l:?}")))
            })
            .collect::<Result<_>>()?;
        let vocab: Vocab = map.into_iter().collect();
        Self::build(vocab, pairs, padding)
    }

    fn build(vocab: Vocab, merges: Vec<(String, String)>, padding: ClipPadding) -> Result<Self> {
        let bpe = BPE::builder()
            .vocab_and_merges(vocab, merges)
            .end_of_word_suffix("</w>".into())
            .build()
            .map_err(|e| Error::invalid(format!("CLIP tokenizer: {e}")))?;
        let bad = |e: tokenizers::Error| Error::invalid(format!("CLIP tokenizer: {e}"));
        let normalizer = NormalizerSequence::new(vec![
            NFC.into(),
            Replace::new(
                tokenizers::normalizers::replace::ReplacePattern::Regex(r"\s+".into()),
                " ",
            )
            .map_err(bad)?
            .into(),
            Lowercase.into(),
        ]);
        let pre = PreTokenizerSequence::new(vec![
            Split::new(
                SplitPattern::Regex(PATTERN.into()),
                SplitDelimiterBehavior::Removed,
                true,
            )
            .map_err(bad)?
            .into(),
            ByteLevel::new(false, true, false).into(),
        ]);
        let mut inner = Tokenizer::new(bpe);
        inner.with_normalizer(Some(normalizer)).map_err(bad)?;
        inner.with_pre_tokenizer(Some(pre));
        Ok(Self { inner, padding })
    }

    /// The prompt's 77 ids: BOS, up to 75 tokens, EOS, padding.
    pub fn encode(&self, prompt: &str) -> Result<ClipTokens> {
        let encoding = self
            .inner
            .encode(prompt.trim(), false)
            .map_err(|e| Error::invalid(format!("CLIP tokenizer: {e}")))?;
        let body = encoding.get_ids();
        let room = CONTEXT_LENGTH - 2;
        let kept = &body[..body.len().min(room)];
        let mut ids = Vec::with_capacity(CONTEXT_LENGTH);
        ids.push(BOS);
        ids.extend_from_slice(kept);
        ids.push(EOS);
        let pad = match self.padding {
            ClipPadding::EndOfText => EOS,
            ClipPadding::Zero => 0,
        };
        ids.resize(CONTEXT_LENGTH, pad);
        Ok(ClipTokens {
            ids,
            prompt_tokens: body.len(),
            truncated: body.len() > room,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The real merges list, when tests/run.sh fetched it (open-clip-torch's wheel, MIT).
    fn real() -> Option<ClipTokenizer> {
        let path = std::env::var_os("MAKEIT4D_CLIP_BPE")?;
        Some(ClipTokenizer::from_clip_merges_gz(Path::new(&path), ClipPadding::EndOfText).unwrap())
    }

    fn body(t: &ClipTokens) -> Vec<u32> {
        let end = t.ids.iter().position(|&i| i == EOS).unwrap();
        t.ids[..=end].to_vec()
    }

    #[test]
    fn the_real_vocabulary_gives_clips_known_answers() {
        let Some(tok) = real() else {
            assert!(
                std::env::var_os("CI").is_none(),
                "CI needs MAKEIT4D_CLIP_BPE (tests/run.sh fetches it)"
            );
            return;
        };
        let cat = tok.encode("a photo of a cat").unwrap();
        assert_eq!(body(&cat), [49406, 320, 1125, 539, 320, 2368, 49407]);
        assert_eq!(cat.ids.len(), 77);
        assert!(cat.ids[7..].iter().all(|&i| i == EOS));
        assert_eq!(
            body(&tok.encode("Hello, world!").unwrap()),
            [49406, 3306, 267, 1002, 256, 49407]
        );
        assert_eq!(body(&tok.encode("").unwrap()), [49406, 49407]);
        // Case and runs of whitespace do not matter.
        assert_eq!(tok.encode("A   PHOTO of a\tcat").unwrap(), cat);
        // 10 000 characters: cut to 75 tokens of text, said.
        let long = tok
            .encode(&"sunset over a quiet lake ".repeat(400))
            .unwrap();
        assert!(long.truncated && long.prompt_tokens > 75);
        assert_eq!((long.ids[0], long.ids[76]), (BOS, EOS));
    }

    #[test]
    fn a_tiny_vocabulary_pads_as_each_family_does() {
        // A merges list of "c a" first, padded out to CLIP's count with merges of other pairs
        // of byte symbols.
        let mut text = String::from("#version: 0.2\nc a\n");
        let symbols = byte_symbols();
        let mut k = 0;
        'outer: for a in &symbols {
            for b in &symbols {
                if k + 1 == CLIP_MERGES {
                    break 'outer;
                }
                if (*a, *b) != ('c', 'a') {
                    text.push_str(&format!("{a} {b}\n"));
                    k += 1;
                }
            }
        }
        assert_eq!(byte_symbols().len(), 256);
        assert_eq!(byte_symbols()[0], '!');
        let eos = ClipTokenizer::from_clip_merges(&text, ClipPadding::EndOfText).unwrap();
        let zero = ClipTokenizer::from_clip_merges(&text, ClipPadding::Zero).unwrap();
        let a = eos.encode("ca").unwrap();
        let b = zero.encode("ca").unwrap();
        // "ca" ends a word: no merge makes "ca</w>", so c then a</w>.
        assert_eq!(a.ids[0], BOS);
        assert_eq!(a.ids[a.prompt_tokens + 1], EOS);
        assert_eq!(a.ids[76], EOS);
        assert_eq!(b.ids[76], 0);
        assert_eq!(a.ids[..a.prompt_tokens + 2], b.ids[..b.prompt_tokens + 2]);
        // A list that is not one is refused by what is wrong.
        assert!(ClipTokenizer::from_clip_merges("#version\na b c\n", ClipPadding::Zero).is_err());
        assert!(ClipTokenizer::from_clip_merges("#version\na b\n", ClipPadding::Zero).is_err());
    }
}
